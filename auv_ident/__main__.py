"""python -m auv_ident ..."""
import sys

from .cli import main

sys.exit(main())

"""python -m auv_ident ..."""
import sys

from auv_ident.cli import main

sys.exit(main())

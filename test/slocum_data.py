"""Where the tests find the Slocum glider "comet" data (Baltic, 23 June 2016, from the public
repository smerckel/gliderflight, MIT): ../shared/realdata/slocum_comet relative to the
repository root (or to a folder above it: a git worktree under ../wt/ reads the same copy),
never committed to the project. :func:`require` skips a test without them."""
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SLOCUM_DIR = next((d / 'shared' / 'realdata' / 'slocum_comet' for d in REPO.parents
                   if (d / 'shared' / 'realdata' / 'slocum_comet').is_dir()),
                  REPO.parent / 'shared' / 'realdata' / 'slocum_comet')
NPY_NAME = 'gliderflight_data.npy'


def require():
    """The data directory, or a skip saying where it was looked for."""
    if not (SLOCUM_DIR / NPY_NAME).is_file() or not sorted(SLOCUM_DIR.glob('*.dbd')):
        pytest.skip(f'Slocum glider data not found in {SLOCUM_DIR} (public data from '
                    'smerckel/gliderflight, not part of the repository)')
    return SLOCUM_DIR

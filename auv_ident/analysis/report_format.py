"""Formatting shared by the report's sections: matplotlib off-screen, figure files, Markdown
table cells and tables, and the versions a report records."""
import math
import platform

import numpy as np

from auv_ident import __version__


def pyplot():
    """matplotlib.pyplot on the off-screen Agg backend (reports are written on servers)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def save_figure(fig, path):
    """Write fig as PNG (110 dpi) to path, close it, return path."""
    fig.savefig(path, dpi=110)
    pyplot().close(fig)
    return path


def cell(v):
    """A table cell: 6 significant digits (the tests parse these back), '-' when unknown or
    not a number, 'inf' for an infinity."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return '-'
    if isinstance(v, float) and math.isinf(v):
        return 'inf' if v > 0 else '-inf'
    return f'{v:.6g}' if isinstance(v, (int, float)) else str(v)


def finite_cell(v, fmt='.4g'):
    """A table cell of a float that may be missing or non-finite: '-' then, right-aligned to
    the width the format asks for (so that fixed-width text tables keep their columns)."""
    if v is not None and np.isfinite(v):
        return format(v, fmt)
    width = ''.join(ch for ch in fmt.split('.')[0] if ch.isdigit())
    return format('-', '>' + width) if width else '-'


def package_versions():
    """The versions of the package and of what its numbers depend on (a report records them)."""
    import matplotlib
    import numba
    import scipy
    return {'auv_ident': __version__, 'numpy': np.__version__, 'scipy': scipy.__version__,
            'numba': numba.__version__, 'matplotlib': matplotlib.__version__,
            'python': platform.python_version()}


def markdown_table(header, rows):
    """A Markdown table of a header and rows of cells (strings)."""
    out = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    out += ['| ' + ' | '.join(r) + ' |' for r in rows]
    return '\n'.join(out)

"""The monomial part of F, compiled per vehicle: generated straight-line code from the term table.

F's hydrodynamic, control and rigid-body Coriolis terms are monomials k c_i z_a z_b ... over the
factor vector z (vehicle.FACTORS); their table (vehicle.terms_i, terms_s) is data from the
vehicle file. A loop that reads the table at run time spends most of its time on the table
itself (index loads, branches on the factor count, a read-modify-write of xdot and A per term):
0.55 us of each model evaluation, four per EKF step. This module writes the table out as Python
source with every index a constant, compiles it once with numba as a C callback of signature
SIG, and keeps it in a file cache keyed on the source (a private folder of the user's, never the
package: _cache_dirs), so each vehicle structure is compiled once per user (about 5 s) and
loaded in about 0.3 s per process after that. It evaluates in about a third of the loop's time
(0.54 -> 0.16 us), and gives bit-identical results: every output is accumulated in the table's
order from its current value, as the loop did.

The kernel does not depend on which coefficients are identified: it writes dprod[ci], the
derivative of F by coefficient ci (its term's scale times its factor product; each coefficient
has one term, vehicle.py), and the caller gathers df/dtheta from those of theta
(Model.theta_terms).
"""
from collections import defaultdict
from collections.abc import Iterator
import hashlib
import importlib.util
import os
import sys
from typing import Any

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic
import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.safe_files import ensure_content, make_private, private_candidates

NZ = 21          # length of the factor vector z (vehicle.FACTORS); zz = [z, dz/dx, dU/dv]
N_STATE_FACTORS = 12   # z[0:6] = u..r (dz/dx = 1), z[6:12] = |u|..|r| (dz/dx = sign)
Z_EPS = 18             # propeller epsilon (dz/du from the propulsion model)
# the speed U = sqrt(u^2 + v^2): the one factor of two states, dU/du in zz[NZ + Z_SPEED] as
# for the others and dU/dv in zz[ZZ_DU_DV]
Z_SPEED = 19
Z_THRUST = 20          # measured thrust (an input: no state derivative)
ZZ_DU_DV = 2 * NZ

# monomial_terms(c, zz, want_jac, xdot, A, dprod): c (n_coef,) coefficient values; zz (2 NZ,)
# factors and their derivatives; xdot (12,) and A (12 x 12) accumulated in rows 0..5;
# dprod (n_coef,) written for the coefficients that have a term (with want_jac).
SIG = types.void(types.float64[::1], types.float64[::1], types.boolean, types.float64[::1],
                 types.float64[:, ::1], types.float64[::1])

MONO_TYPE = types.FunctionType(SIG)

# key -> cfunc; kept for the life of the process (its address is handed out)
_loaded: dict[str, Any] = {}


@intrinsic
def kernel_at(typingctx, address):
    """Inside compiled code: the monomial kernel at `address` (monomial_kernel(...).address),
    as a callable. The model's callers take the kernel as this plain integer rather than as
    the cfunc object, because numba types a cfunc argument in Python at every call from
    Python (about 16 us, three times the model's own cost for the per-message API)."""
    if not isinstance(address, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        f = cgutils.create_struct_proxy(MONO_TYPE)(context, builder)
        null = context.get_constant_null(types.voidptr)
        f.c_addr = builder.inttoptr(args[0], cgutils.voidptr_t)   # called through this
        f.py_addr = null
        f.jit_addr = null
        return f._getvalue()
    return MONO_TYPE(address), codegen


def _factor_derivatives(f: int) -> list[tuple[int, str]]:
    """[(state column, source of the factor ' * dz_f/dx_column')] of factor f: '' where the
    derivative is 1 (u..r: a product by 1.0 is exact, so leaving it out changes no bit); none
    for the inputs (fins, their sum, the thrust)."""
    if f < 6:
        return [(f, '')]
    if f < N_STATE_FACTORS or f == Z_EPS:
        return [(f % 6, f' * d{f}')]
    if f == Z_SPEED:
        return [(0, f' * d{f}'), (1, ' * dUv')]
    return []


def kernel_source(terms_i: np.ndarray, terms_s: np.ndarray) -> str:
    """Python source of the monomial kernel for a term table (see the module docstring)."""
    rows = []
    seen = set()
    for t in range(terms_i.shape[0]):
        eq, ci = int(terms_i[t, 0]), int(terms_i[t, 1])
        if ci >= 0 and ci in seen:
            raise ConfigError(f'coefficient #{ci} has more than one term in the term table')
        seen.add(ci)
        fs = [int(f) for f in terms_i[t, 2:] if f >= 0]
        if not np.isfinite(terms_s[t]):     # repr gives 'inf'/'nan': no Python literal
            raise ConfigError(f'term {t} of the term table has the scale '
                              f'{float(terms_s[t])!r}, not a finite number')
        rows.append((t, eq, ci, fs, float(terms_s[t])))
    used = sorted({f for _, _, _, fs, _ in rows for f in fs})
    L = ['def monomial_terms(c, zz, want_jac, xdot, A, dprod):']
    L += [f'    z{f} = zz[{f}]' for f in used]
    for t, eq, ci, fs, s in rows:
        L.append(f'    k{t} = {s!r}' + (f' * c[{ci}]' if ci >= 0 else ''))
        L.append(f'    p{t} = ' + (' * '.join(f'z{f}' for f in fs) or '1.0'))
    # xdot: per equation, from its current value, in table order (as the loop summed)
    eqs = sorted({eq for _, eq, _, _, _ in rows})
    L += [f'    x{eq} = xdot[{eq}]' for eq in eqs]
    L += [f'    x{eq} += k{t} * p{t}' for t, eq, _, _, _ in rows]
    L += [f'    xdot[{eq}] = x{eq}' for eq in eqs]
    L.append('    if not want_jac:')
    L.append('        return')
    L += [f'    d{f} = zz[{NZ + f}]' for f in used
          if any(dz for _, dz in _factor_derivatives(f))]
    if Z_SPEED in used:
        L.append(f'    dUv = zz[{ZZ_DU_DV}]')
    acc = defaultdict(list)      # (eq, column) -> accumulation lines, in table order
    for t, eq, _, fs, _ in rows:
        for j, f in enumerate(fs):
            rest = f'k{t}'
            for jj, g in enumerate(fs):
                if jj != j:
                    rest += f' * z{g}'
            for col, dz in _factor_derivatives(f):
                acc[(eq, col)].append(f'        a += {rest}{dz}')
    for (eq, col), lines in sorted(acc.items()):
        L.append(f'    a = A[{eq}, {col}]')
        L += [ln[4:] for ln in lines]
        L.append(f'    A[{eq}, {col}] = a')
    L += [f'    dprod[{ci}] = {s!r} * p{t}' for t, _, ci, _, s in rows if ci >= 0]
    return '\n'.join(L) + '\n'


def _cache_dirs() -> Iterator[str]:
    """Where the generated kernels may go, best first: $AUV_IDENT_KERNEL_CACHE if set, then the
    user's private cache folder (core/safe_files.py private_candidates); never the package."""
    env = os.environ.get('AUV_IDENT_KERNEL_CACHE')
    if env:
        yield env
    yield from private_candidates('kernels')


def _write_source(name: str, text: str) -> str:
    """Write the kernel's module to the first usable cache folder (created 0700, checked to be
    the user's own and no symbolic link: its files are imported), through a temporary file of
    that folder renamed into place (several processes may compile the same vehicle at once).
    Returns its path."""
    tried = []
    env = os.environ.get('AUV_IDENT_KERNEL_CACHE')
    for d in _cache_dirs():
        path = os.path.join(d, name + '.py')
        try:
            make_private(d, parent=d != env)     # a folder the user named: itself only
            return str(ensure_content(path, text, mode=0o600))
        except OSError as err:
            tried.append(f'{d} ({err.strerror or err})')
    raise ConfigError('no usable folder for the compiled model kernel; set '
                      'AUV_IDENT_KERNEL_CACHE (tried: ' + ', '.join(tried) + ')')


def monomial_kernel(terms_i: np.ndarray, terms_s: np.ndarray) -> Any:
    """The compiled kernel (a numba cfunc of signature SIG) for this term table."""
    body = kernel_source(terms_i, terms_s)
    key = hashlib.sha256((str(SIG) + body).encode()).hexdigest()[:20]
    if key in _loaded:
        return _loaded[key]
    name = f'auv_ident_monomials_{key}'
    text = ('# Generated by auv_ident.core.model.monomials from a vehicle term table: do not '
            'edit.\n'
            'from numba import cfunc\n\n'
            'from auv_ident.core.model.monomials import SIG\n\n\n'
            '@cfunc(SIG, cache=True)\n' + body)
    path = _write_source(name, text)
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None     # a .py file path always has both
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    _loaded[key] = module.monomial_terms
    return module.monomial_terms

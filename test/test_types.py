"""The typed public API: mypy on core/ and the session's message, record, estimate-file,
diagnosis, screening and warning modules, with setup.cfg's [mypy] sections (every function
annotated there: disallow_untyped_defs), and not one error.

The numba kernels are left unannotated: numba types them from their arguments at compile time,
and an annotation there would be a second, unchecked statement of the same thing. They are
excepted by name: the functions compiled through one of KERNEL_DECORATORS, and the functions
defined inside them (the intrinsic's code generator)."""
import ast
import os
from pathlib import Path
import re
import subprocess
import sys
import tempfile

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / 'auv_ident'
SESSION_TYPED = ('messages', 'record', 'estimate_file', 'live_diagnosis', 'screening',
                 'warning_limiter', 'input_map', 'inputs')
TARGETS = [PKG / 'core'] + [PKG / 'session' / f'{m}.py' for m in SESSION_TYPED]
# the numba decorators of the core: compiled_cache.cached_njit, the kernel = cached_njit(...)
# shorthands of the model modules, numba.extending.intrinsic
KERNEL_DECORATORS = {'cached_njit', 'kernel', 'intrinsic'}
# mypy's cache outside the repository, kept between runs (a cold run takes about 15 s)
CACHE = Path(tempfile.gettempdir()) / f'auv_ident-mypy-{os.getuid()}'
_ERROR = re.compile(r'^(?P<path>[^:]+):(?P<line>\d+): error: (?P<text>.*)\[(?P<code>[\w-]+)\]$')


def _mypy(*args, cwd=ROOT, cache=CACHE):
    try:
        import mypy  # noqa: F401
    except ImportError:
        pytest.skip('mypy is not installed (requirements.txt installs it)')
    return subprocess.run([sys.executable, '-m', 'mypy', '--cache-dir', str(cache),
                           '--no-error-summary', '--show-error-codes', *map(str, args)],
                          capture_output=True, text=True, cwd=cwd)


def _decorators(f):
    names = set()
    for d in f.decorator_list:
        d = d.func if isinstance(d, ast.Call) else d
        names.add(d.attr if isinstance(d, ast.Attribute) else getattr(d, 'id', ''))
    return names


def kernel_lines(path):
    """{def line: name} of the numba kernels of a source file (module docstring)."""
    out = {}

    def walk(node, inside):
        for n in ast.iter_child_nodes(node):
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
                kernel = inside or bool(_decorators(n) & KERNEL_DECORATORS)
                if kernel:
                    out[n.lineno] = n.name
                walk(n, kernel)
            else:
                walk(n, inside)
    walk(ast.parse(Path(path).read_text()), False)
    return out


def real_errors(stdout, root=ROOT):
    """mypy's error lines but the missing annotations of numba kernels (paths relative to
    root, where mypy ran, or absolute)."""
    kernels = {}
    errors = []
    for line in stdout.splitlines():
        m = _ERROR.match(line.strip())
        if m is None:
            continue
        path = root / m['path']
        if m['code'] == 'no-untyped-def':
            if path not in kernels:
                kernels[path] = kernel_lines(path)
            if int(m['line']) in kernels[path]:
                continue
        errors.append(line)
    return errors


def test_the_typed_modules_pass_mypy():
    r = _mypy('--config-file', ROOT / 'setup.cfg', *TARGETS)
    assert r.returncode in (0, 1), r.stderr
    errors = real_errors(r.stdout)
    assert not errors, '\n'.join(errors)


def test_every_typed_module_disallows_untyped_defs():
    """setup.cfg lists every typed module for disallow_untyped_defs (core/ as a whole)."""
    text = (ROOT / 'setup.cfg').read_text()
    section = re.search(r'^\[mypy-(auv_ident\.core\.\*[^\]]*)\]\s*\n(?:[^\[]*\n)*?'
                        r'disallow_untyped_defs = True', text, re.M)
    assert section, 'no [mypy-auv_ident.core.*,...] section with disallow_untyped_defs'
    listed = set(section[1].split(','))
    assert {f'auv_ident.session.{m}' for m in SESSION_TYPED} <= listed


def test_mypy_sees_an_error_and_a_missing_annotation(tmp_path):
    """A check that reported nothing would pass on any code: a wrong argument type and an
    unannotated function are both errors, and only a numba kernel's missing annotations are
    excepted."""
    bad = tmp_path / 'bad.py'
    bad.write_text('from auv_ident.core.compiled_cache import cached_njit\n\n\n'
                   'def half(x: float) -> float:\n    return x / 2\n\n\n'
                   'def untyped(x):\n    return half("one")\n\n\n'
                   '@cached_njit()\ndef kernel_like(x):\n    return x\n')
    r = _mypy('--disallow-untyped-defs', '--ignore-missing-imports', '--follow-imports',
              'silent', bad, cwd=ROOT, cache=tmp_path / 'cache')   # its own: the path moves
    assert r.returncode == 1, r.stdout + r.stderr
    errors = real_errors(r.stdout)
    assert [(e.split(':')[1], e.rsplit('[', 1)[1]) for e in errors] == [
        ('8', 'no-untyped-def]'), ('9', 'arg-type]')], r.stdout
    assert 'bad.py:13: error' in r.stdout          # the kernel: seen by mypy, then excepted

"""The house lint on the package, its tests and tools: ament_flake8's rules for ROS 2 Python
packages (99 columns, single quotes, google import order, no shadowed builtins, pyflakes and
pycodestyle errors) and the complexity gate (mccabe at most 15 per function), run by ruff with
tools/ruff.toml."""
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'tools' / 'ruff.toml'


def _ruff():
    exe = Path(sys.executable).parent / 'ruff'
    found = str(exe) if exe.is_file() else shutil.which('ruff')
    if found is None:
        pytest.skip('ruff is not installed (requirements.txt installs it)')
    return found


def _run(*paths, cwd=ROOT):
    return subprocess.run([_ruff(), 'check', '--config', str(CONFIG), '--no-cache',
                           '--output-format', 'concise', *map(str, paths)],
                          capture_output=True, text=True, cwd=cwd)


def test_package_tests_and_tools_pass_the_lint():
    r = _run('auv_ident', 'test', 'tools')
    assert r.returncode == 0, r.stdout + r.stderr


def test_the_lint_sees_a_violation(tmp_path):
    """A lint that saw nothing would pass on any code: double quotes, a shadowed builtin, an
    unused import, imports out of order, a 100-column line and a function of complexity 16
    are each reported."""
    bad = tmp_path / 'bad.py'
    branches = ''.join(f'    if x == {i}:\n        return {i}\n' for i in range(15))
    bad.write_text('import sys\nimport os\n\nlist = "x"\nY = 1' + ' ' * 90 + '# long\n\n\n'
                   'def tangled(x):\n' + branches + '    return -1\n')
    r = _run(bad, cwd=tmp_path)
    assert r.returncode == 1
    for code in ('F401', 'I001', 'A001', 'Q000', 'E501', 'C901'):
        assert code in r.stdout, (code, r.stdout)

"""colcon build of the package (as on a ROS machine) into tmp_path, and its executables run.

The build works on a copy of the repository's files (git's tracked + untracked-not-ignored
files), so the working tree stays untouched whatever colcon/setuptools write; the copy is
also checked to stay unchanged (colcon keeps egg-info and build files in --build-base).
"""
import os
from pathlib import Path
import shutil
import subprocess
import sys

from conftest import require_loopback_dds
import helpers
import pytest

pytestmark = pytest.mark.slow     # a colcon build and the installed executables

REPO = Path(helpers.REPO)
VENV_BIN = Path(sys.executable).parent
PKG = 'auv_ident'
EXECUTABLES = ('simulator', 'identifier', 'record', 'play')
_SKIP_DIRS = {'.git', '.venv', 'build', 'install', 'log', '__pycache__', '.pytest_cache'}


def _source_files():
    """Relative paths of the package's source files (git's view if there is a .git)."""
    if (REPO / '.git').exists() and shutil.which('git'):
        out = subprocess.run(
            ['git', 'ls-files', '-z', '--cached', '--others', '--exclude-standard'],
            cwd=REPO, capture_output=True, check=True).stdout
        return [Path(p) for p in out.decode().split('\0') if p and (REPO / p).is_file()]
    files = []
    for root, dirs, names in os.walk(REPO):
        dirs[:] = [d for d in dirs if d not in _SKIP_DIRS and not d.endswith('.egg-info')]
        files += [Path(root, n).relative_to(REPO) for n in names if not n.endswith('.pyc')]
    return files


def _tree(path):
    return sorted(str(p.relative_to(path)) for p in path.rglob('*'))


@pytest.fixture(scope='module')
def install(tmp_path_factory):
    """colcon build --packages-select auv_ident; return the install base."""
    base = tmp_path_factory.mktemp('colcon')
    src = base / 'src' / PKG
    for rel in _source_files():
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, src / rel)
    before = _tree(src)
    env = dict(os.environ, PATH=f'{VENV_BIN}{os.pathsep}{os.environ.get("PATH", "")}',
               COLCON_HOME=str(base / 'colcon_home'))
    proc = subprocess.run(
        [str(VENV_BIN / 'colcon'), '--log-base', str(base / 'log'), 'build',
         '--base-paths', str(base / 'src'), '--build-base', str(base / 'build'),
         '--install-base', str(base / 'install'), '--packages-select', PKG],
        cwd=base, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert f'Finished <<< {PKG}' in proc.stdout
    assert _tree(src) == before, 'colcon wrote into the source tree'
    return base / 'install'


def test_install_layout(install):
    lib = install / PKG / 'lib' / PKG
    for name in EXECUTABLES:
        exe = lib / name
        assert exe.is_file() and os.access(exe, os.X_OK), exe
    share = install / PKG / 'share'
    assert (share / PKG / 'config' / 'nps_auv2.yaml').is_file()
    assert (share / PKG / 'package.xml').is_file()
    assert (share / 'ament_index' / 'resource_index' / 'packages' / PKG).is_file()
    assert (install / 'setup.bash').is_file()


def _sourced(install, command, env):
    """Run command in bash after sourcing the install's setup.bash (as `ros2 run` would)."""
    require_loopback_dds()
    script = f'. "{install}/setup.bash" && {command}'
    return subprocess.run(['bash', '-c', script], env=env, capture_output=True, text=True,
                          timeout=60, cwd=install.parent)


def test_installed_executables_run(install, ros_env):
    env = dict(ros_env, PATH=f'{VENV_BIN}{os.pathsep}{ros_env.get("PATH", "")}')
    lib = install / PKG / 'lib' / PKG
    # the installed package, not the working tree's editable install, is what gets imported
    proc = _sourced(install, f'"{sys.executable}" -c "import auv_ident.ros.play_node as m; '
                             'print(m.__file__)"', env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().startswith(str(install / PKG / 'lib')), proc.stdout

    proc = _sourced(install, f'"{lib}/play" --ros-args -p bag:=/nonexistent/run1', env)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, proc.stderr
    assert 'Traceback' not in proc.stderr
    assert len(lines) == 1 and '/nonexistent/run1' in lines[0], proc.stderr

    proc = _sourced(install, f'"{lib}/record" --help', env)
    assert proc.returncode == 0, proc.stderr
    assert 'topics' in proc.stdout and 'output' in proc.stdout

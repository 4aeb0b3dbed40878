"""package.xml declares every run and test dependency: each third-party module the package
imports maps to an exec_depend, each one only the tests import to a test_depend (or an
exec_depend), and the tools the tests run (ruff, mypy, pytest-timeout, colcon) are test_depends;
a rosdep key rosdistro lacks is defined in tools/rosdep.yaml."""
import ast
from pathlib import Path
import sys
import xml.etree.ElementTree as ET

import yaml

ROOT = Path(__file__).resolve().parents[1]
STDLIB = set(sys.stdlib_module_names)

# import name -> rosdep key (a ROS package's import name is its key, e.g. rclpy, std_msgs)
ROSDEP_KEY = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml',
    'numba': 'python3-numba', 'matplotlib': 'python3-matplotlib',
    'mcap': 'python3-mcap-pip', 'mcap_ros2': 'mcap-ros2-support',
    'rosbags': 'python3-rosbags-pip', 'filterpy': 'python3-filterpy-pip',
    'dask': 'python3-dask-pip', 'distributed': 'python3-distributed-pip',
    'pytest': 'python3-pytest', 'mypy': 'python3-mypy',
}
ROS_PACKAGES = {'rclpy', 'std_msgs', 'std_srvs', 'nav_msgs', 'sensor_msgs', 'geometry_msgs',
                'diagnostic_msgs', 'rosgraph_msgs', 'rcl_interfaces', 'builtin_interfaces',
                'ament_index_python'}
# what the tests run rather than import: the lint (test_lint), the type check (test_types),
# the per-test timeout (setup.cfg), the colcon build (ros/test_colcon_build)
TEST_TOOLS = {'python3-ruff-pip', 'python3-mypy', 'python3-pytest-timeout',
              'python3-colcon-common-extensions'}
# the keys of rosdistro's rosdep/python.yaml this file relies on (checked 2026-11)
IN_ROSDISTRO = {'python3-numpy', 'python3-scipy', 'python3-yaml', 'python3-numba',
                'python3-matplotlib', 'mcap-ros2-support', 'python3-rosbags-pip',
                'python3-filterpy-pip', 'python3-pytest', 'python3-pytest-timeout',
                'python3-ruff-pip', 'python3-mypy', 'python3-colcon-common-extensions',
                'python3-cryptography'}


def _declared():
    root = ET.parse(ROOT / 'package.xml').getroot()
    deps = {}
    for tag in ('depend', 'exec_depend', 'test_depend', 'build_depend'):
        for e in root.iter(tag):
            deps.setdefault(tag, set()).add(e.text.strip())
    return deps


def _third_party_imports(folder):
    """Top-level module names imported anywhere in the .py files below `folder` that are
    neither the standard library, the package nor a module of `folder` itself."""
    local = {p.stem for p in folder.rglob('*.py')} | {'auv_ident'}
    names = set()
    for path in folder.rglob('*.py'):
        for n in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(n, ast.Import):
                names |= {a.name.split('.')[0] for a in n.names}
            elif isinstance(n, ast.ImportFrom) and n.level == 0 and n.module:
                names.add(n.module.split('.')[0])
    return names - STDLIB - local


def missing_dependencies(imports, declared, tags):
    """[(module, what is wrong)] for each of `imports` with no rosdep key among the `declared`
    dependencies of the `tags`."""
    have = set().union(*(declared.get(t, set()) for t in tags))
    out = []
    for name in sorted(imports):
        key = name if name in ROS_PACKAGES else ROSDEP_KEY.get(name)
        if key is None:
            out.append((name, 'no rosdep key known: add it to package.xml and ROSDEP_KEY'))
        elif key not in have:
            out.append((name, f'{key} is not a {" or ".join(tags)} of package.xml'))
    return out


def test_every_import_of_the_package_is_an_exec_depend():
    imports = _third_party_imports(ROOT / 'auv_ident')
    assert missing_dependencies(imports, _declared(), ('depend', 'exec_depend')) == []


def test_every_import_of_the_tests_is_declared():
    imports = _third_party_imports(ROOT / 'test')
    assert missing_dependencies(imports, _declared(),
                                ('depend', 'exec_depend', 'test_depend')) == []


def test_the_tools_the_tests_run_are_test_depends():
    assert TEST_TOOLS <= _declared().get('test_depend', set())


def test_keys_rosdistro_lacks_are_defined_here():
    declared = set().union(*_declared().values())
    ours = yaml.safe_load((ROOT / 'tools' / 'rosdep.yaml').read_text())
    for key in declared - ROS_PACKAGES - IN_ROSDISTRO:
        assert key in ours, f'{key}: neither in rosdistro nor in tools/rosdep.yaml'
        assert ours[key]['ubuntu']['pip']['packages'], key


def test_the_check_sees_an_undeclared_import():
    """A check that found nothing would pass on any package.xml: an unknown module and a known
    one left undeclared are both reported."""
    declared = {'exec_depend': {'python3-numpy'}}
    found = missing_dependencies({'numpy', 'pandas', 'scipy', 'rclpy'}, declared,
                                 ('exec_depend',))
    assert [m for m, _ in found] == ['pandas', 'rclpy', 'scipy']

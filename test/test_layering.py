"""The package's layers, checked on the source (every import, also inside functions).

    core  <-  session  <-  offline  <-  ros  <-  cli
    bags (rosbag2 I/O)   <-  offline  <-  analysis  <-  cli

- core/: numpy, scipy, numba, yaml and the standard library only; imports nothing else of the
  package (the library one could publish alone); inside it, sub-packages that import one way:
  model <- filter <- identification, model <- simulation, identification and simulation <-
  glider (errors, angles and compiled_cache at core/ serve them all);
- vehicles.py (vehicle files by name): core only;
- session/: core, vehicles, session; no ROS, no bag library;
- bags/: the rosbag2 MCAP reader, writer, scan and repair: core errors and the bag libraries
  only, never the session, rclpy or *_msgs;
- offline/: the application on bags (replay through the session, imports, simulated runs);
- ros/: the only place rclpy and ROS message packages appear; may use bags/ and offline/;
- analysis/: everything below but ros/, no rclpy;
- no import cycles between modules.
"""
import ast
from pathlib import Path
import sys

import pytest

PKG = Path(__file__).resolve().parents[1] / 'auv_ident'
STDLIB = set(sys.stdlib_module_names)

# layer -> package layers it may import
ALLOWED_INTERNAL = {
    'core': {'core'},
    'vehicles': {'core', 'vehicles'},
    'session': {'core', 'vehicles', 'session'},
    'bags': {'core', 'bags'},
    'offline': {'core', 'vehicles', 'session', 'bags', 'offline'},
    'ros': {'core', 'vehicles', 'session', 'bags', 'offline', 'ros'},
    'analysis': {'core', 'vehicles', 'session', 'bags', 'offline', 'analysis'},
    'top': {'core', 'vehicles', 'session', 'bags', 'offline', 'ros', 'analysis', 'top'},
}
# inside core/: sub-package -> the core parts it may import ('' = core/'s own modules)
CORE_PARTS = {
    '': {''},
    'model': {'', 'model'},
    'filter': {'', 'model', 'filter'},
    'identification': {'', 'model', 'filter', 'identification'},
    'simulation': {'', 'model', 'simulation'},
    # the glider's flight model: its own physics; the sandwich covariance and the fit % of
    # the others, not the 6-DOF model
    'glider': {'', 'identification', 'simulation', 'glider'},
}
ROS_PACKAGES = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'rosgraph_msgs',
                'std_srvs', 'rosidl_runtime_py', 'rpyutils'}
# third-party packages each layer may use (besides the standard library)
ALLOWED_EXTERNAL = {
    'core': {'numpy', 'scipy', 'numba', 'llvmlite', 'yaml'},
    'vehicles': {'numpy', 'yaml', 'ament_index_python'},
    'session': {'numpy', 'scipy', 'yaml'},
    'bags': {'numpy', 'yaml', 'mcap', 'mcap_ros2', 'rosbags', 'zstandard', 'lz4'},
    'offline': {'numpy', 'scipy', 'yaml', 'mcap', 'mcap_ros2', 'rosbags'},
    'analysis': {'numpy', 'scipy', 'numba', 'yaml', 'matplotlib', 'filterpy', 'distributed',
                 'dask', 'mcap', 'rosbags'},
    'ros': None,    # anything
    'top': None,
}


def _module_name(path, pkg=PKG):
    rel = path.relative_to(pkg.parent).with_suffix('')
    parts = list(rel.parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def _layer(module):
    parts = module.split('.')
    if len(parts) == 1:
        return 'top'
    if parts[1] in ALLOWED_INTERNAL:
        return parts[1]
    return 'top'    # cli, __main__


def _core_part(module):
    """'model', 'filter', ... for a module inside core/; '' for core/'s own modules."""
    parts = module.split('.')
    if len(parts) > 3 and parts[2] in CORE_PARTS:
        return parts[2]
    return ''


def _sources():
    return sorted(p for p in PKG.rglob('*.py') if '__pycache__' not in p.parts)


def _imports(path, pkg=PKG):
    """(line, absolute module name) of every import in the file, nested ones included."""
    module = _module_name(path, pkg)
    package = module if path.name == '__init__.py' else module.rpartition('.')[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split('.')
                base = base[:len(base) - node.level + 1]
                target = '.'.join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            out.append((node.lineno, target))
            # 'from pkg import module' names a module too
            out += [(node.lineno, f'{target}.{a.name}') for a in node.names
                    if (pkg.parent / Path(*f'{target}.{a.name}'.split('.'))).with_suffix(
                        '.py').is_file()]
    return out


def _internal_graph():
    modules = {_module_name(p): p for p in _sources()}
    graph = {}
    for name, path in modules.items():
        deps = set()
        for _, target in _imports(path):
            if target in modules and target != name:
                deps.add(target)
        graph[name] = deps
    return graph


def _violations(path, pkg=PKG):
    module = _module_name(path, pkg)
    layer = _layer(module)
    bad = []
    for line, target in _imports(path, pkg):
        root = target.split('.')[0]
        if root == 'auv_ident':
            if target == 'auv_ident':
                continue    # the package itself (__version__)
            if _layer(target) not in ALLOWED_INTERNAL[layer]:
                bad.append(f'line {line}: {target} ({_layer(target)} layer)')
            elif layer == 'core' and _layer(target) == 'core':
                part, other = _core_part(module), _core_part(target)
                if other not in CORE_PARTS[part]:
                    bad.append(f'line {line}: {target} (core/{other}, from core/{part})')
            continue
        if root in STDLIB:
            continue
        allowed = ALLOWED_EXTERNAL[layer]
        is_ros = root in ROS_PACKAGES or root.endswith('_msgs') or root.endswith('_srvs')
        if allowed is None:
            continue
        if is_ros or root not in allowed:
            bad.append(f'line {line}: {target}')
    return module, layer, bad


@pytest.mark.parametrize('path', _sources(), ids=lambda p: str(p.relative_to(PKG.parent)))
def test_every_import_respects_the_layers(path):
    module, layer, bad = _violations(path)
    assert not bad, f'{module} ({layer} layer) imports what its layer may not: ' + '; '.join(bad)


def test_no_import_cycles():
    graph = _internal_graph()
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, f'import cycles: {cycles}'


def test_the_checks_see_a_violation(tmp_path):
    """The import reader finds imports inside functions and resolves relative ones (a check
    that saw nothing would pass on any code)."""
    pkg = tmp_path / 'auv_ident'
    (pkg / 'core').mkdir(parents=True)
    (pkg / 'ros').mkdir()
    (pkg / 'ros' / 'conversions.py').write_text('')
    fake = pkg / 'core' / 'probe.py'
    fake.write_text('def f():\n    from ..ros import conversions\n    import rclpy\n')
    found = [t for _, t in _imports(fake, pkg)]
    assert 'auv_ident.ros.conversions' in found and 'rclpy' in found
    module, layer, bad = _violations(fake, pkg)
    assert (module, layer) == ('auv_ident.core.probe', 'core')
    assert 'line 2: auv_ident.ros.conversions (ros layer)' in bad and 'line 3: rclpy' in bad


def test_the_checks_see_a_core_part_importing_against_the_order(tmp_path):
    pkg = tmp_path / 'auv_ident'
    for part in ('model', 'filter'):
        (pkg / 'core' / part).mkdir(parents=True)
    (pkg / 'core' / 'filter' / 'ekf.py').write_text('')
    fake = pkg / 'core' / 'model' / 'probe.py'
    fake.write_text('from auv_ident.core.filter import ekf\n')
    module, layer, bad = _violations(fake, pkg)
    assert bad == ['line 1: auv_ident.core.filter.ekf (core/filter, from core/model)']

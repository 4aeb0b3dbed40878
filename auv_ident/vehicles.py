"""Vehicle files by name: where the `config/` folder is (source tree, colcon install, pip
prefix) and :func:`load_vehicle`. The core reads a vehicle from a path
(:func:`auv_ident.core.model.vehicle.vehicle_from_file`); finding it by name needs the ament index
of
a ROS install, so it lives here, outside the core."""
import os
import sys

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.vehicle import Vehicle, vehicle_from_file


def config_dir():
    """Folder of the vehicle YAMLs: the source tree's `config/`, or the installed share dir."""
    here = os.path.dirname(os.path.abspath(__file__))
    candidates = [os.path.join(here, '..', 'config')]
    try:  # colcon / ros2 install: share/auv_ident/config
        from ament_index_python.packages import get_package_share_directory
        candidates.append(os.path.join(get_package_share_directory('auv_ident'), 'config'))
    except Exception:  # noqa: BLE001 - ament index absent outside a ROS install
        pass
    candidates.append(os.path.join(sys.prefix, 'share', 'auv_ident', 'config'))
    for c in candidates:
        if os.path.isdir(c):
            return os.path.abspath(c)
    raise ConfigError('cannot find the auv_ident config/ folder (looked in: '
                      + ', '.join(os.path.abspath(c) for c in candidates) + ')')


def available_vehicles():
    """Names of the vehicle files in config/ (those with a `coefficients:` block)."""
    out = []
    d = config_dir()
    for fn in sorted(os.listdir(d)):
        if fn.endswith('.yaml'):
            with open(os.path.join(d, fn), encoding='utf-8') as fh:
                if '\ncoefficients:' in fh.read():
                    out.append(fn[:-5])
    return out


def resolve_vehicle_path(name_or_path):
    """A vehicle name (file in config/) or a path to a YAML file."""
    if os.path.sep in name_or_path or name_or_path.endswith('.yaml'):
        path = name_or_path
    else:
        path = os.path.join(config_dir(), name_or_path + '.yaml')
    if not os.path.isfile(path):
        raise ConfigError(f'unknown vehicle {name_or_path!r}: no file {path} '
                          f'(available: {", ".join(available_vehicles())})')
    return path


def load_vehicle(name_or_path):
    """Load and validate a vehicle by name (a file in config/) or path (parsed once per file).
    A Vehicle is returned as it is: a command resolves its vehicle once and passes it whole."""
    if isinstance(name_or_path, Vehicle):
        return name_or_path
    return vehicle_from_file(resolve_vehicle_path(name_or_path))

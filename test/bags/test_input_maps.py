"""One run, four bags: today's layout (/odom + /actuators with the six joint names) and the same
run under renamed topics with the commands as a JointState with other joint names, as a
Stonefish-style Float64MultiArray (degrees, PWM), and as one Float64 topic per actuator
published on change. Each, replayed through its input map, identifies what the default layout
does: to the bit where the units are the default's, to rounding where they are not. A map that
names a topic the bag lacks is one error, exit 2 on the command line."""
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
import yaml

from auv_ident.bags.reader import message_counts
from auv_ident.cli import main as cli_main
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import INPUT_NAMES
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.replay import BagInputError, replay_bag
from auv_ident.offline.sim_bag import (
    noise_covariances,
    odometry_msg,
    run_metadata,
    SIM_EPOCH_NS,
    write_message_bag,
    write_run_bag,
)
from auv_ident.session.input_map import InputMapError
from auv_ident.session.messages import RPM_TO_RAD_S, sec_to_ns
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

T = get_typestore(Stores.ROS2_JAZZY).types
FINS = INPUT_NAMES[:5]
SHAFT_LIMIT = 1500.0    # nps_auv2 limits.n_rpm
ODOM_ENTRY = {'topic': '/nav/odometry', 'type': 'nav_msgs/msg/Odometry', 'frame': 'ned'}
# the other joint names, in another order; the shaft speed as the joint's velocity (rad/s)
JOINTS = {'delta_bs': 'bow_s_fin', 'delta_r': 'rudder_joint', 'delta_bp': 'bow_p_fin',
          'delta_s': 'elevator_joint', 'delta_b': 'bow_fin', 'n_rpm': 'prop_joint'}
# Float64MultiArray index of each actuator; fins in degrees, the shaft as a PWM (us)
INDEX = {'delta_r': 3, 'delta_s': 0, 'delta_b': 5, 'delta_bp': 1, 'delta_bs': 2, 'n_rpm': 4}


def _time(msg_stamp):
    return T['builtin_interfaces/msg/Time'](sec=msg_stamp // 10**9, nanosec=msg_stamp % 10**9)


def _header(t_ns):
    return T['std_msgs/msg/Header'](stamp=_time(t_ns), frame_id='')


def _odometry(run, k, t_ns):
    pose_cov, twist_cov = noise_covariances(run.noise_std)
    return odometry_msg(t_ns, run.y[k], 'ned', pose_cov, twist_cov)


def _stamps(run):
    return [SIM_EPOCH_NS + sec_to_ns(float(t)) for t in run.t]


def _joint_bag(run, path):
    names = list(JOINTS.values())
    order = [INPUT_NAMES.index(a) for a in JOINTS]

    def messages():
        for k, t_ns in enumerate(_stamps(run)):
            u = run.u[k]
            position = [float(u[i]) if i < 5 else 0.0 for i in order]
            velocity = [float(u[i]) * RPM_TO_RAD_S if i == 5 else 0.0 for i in order]
            yield '/fins/joint_states', t_ns, T['sensor_msgs/msg/JointState'](
                header=_header(t_ns), name=names, position=np.array(position),
                velocity=np.array(velocity), effort=np.zeros(len(names)))
            yield '/nav/odometry', t_ns, _odometry(run, k, t_ns)
    types = {'/fins/joint_states': 'sensor_msgs/msg/JointState',
             '/nav/odometry': 'nav_msgs/msg/Odometry'}
    write_message_bag(path, types, run_metadata(run), messages())
    channels = [{'joint': j, 'actuator': a} if a != 'n_rpm' else
                {'joint': j, 'field': 'velocity', 'actuator': a, 'unit': 'rad/s'}
                for a, j in JOINTS.items()]
    return {'odom': ODOM_ENTRY, 'fins': {'topic': '/fins/joint_states',
                                         'type': 'sensor_msgs/msg/JointState',
                                         'channels': channels}}


def _array_bag(run, path):
    def messages():
        layout = T['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0)
        for k, t_ns in enumerate(_stamps(run)):
            data = np.zeros(6)
            for a, i in INDEX.items():
                v = float(run.u[k][INPUT_NAMES.index(a)])
                data[i] = np.degrees(v) if a != 'n_rpm' else 1500.0 + 400.0 * v / SHAFT_LIMIT
            yield '/stonefish/setpoints', t_ns, T['std_msgs/msg/Float64MultiArray'](
                layout=layout, data=data)
            yield '/nav/odometry', t_ns, _odometry(run, k, t_ns)
    types = {'/stonefish/setpoints': 'std_msgs/msg/Float64MultiArray',
             '/nav/odometry': 'nav_msgs/msg/Odometry'}
    write_message_bag(path, types, run_metadata(run), messages())
    channels = [{'index': i, 'actuator': a, 'unit': 'us' if a == 'n_rpm' else 'deg'}
                for a, i in INDEX.items()]
    return {'odom': ODOM_ENTRY, 'setpoints': {'topic': '/stonefish/setpoints',
                                              'type': 'std_msgs/msg/Float64MultiArray',
                                              'channels': channels}}


def _float_bag(run, path):
    """One Float64 topic per actuator (the shaft in rad/s), published on change only."""
    actuators = list(INDEX)

    def messages():
        last = {}
        for k, t_ns in enumerate(_stamps(run)):
            for a in actuators:
                v = float(run.u[k][INPUT_NAMES.index(a)])
                v = v * RPM_TO_RAD_S if a == 'n_rpm' else v
                if last.get(a) != v:
                    last[a] = v
                    yield f'/cmd/{a}', t_ns, T['std_msgs/msg/Float64'](data=v)
            yield '/nav/odometry', t_ns, _odometry(run, k, t_ns)
    types = {f'/cmd/{a}': 'std_msgs/msg/Float64' for a in actuators}
    types['/nav/odometry'] = 'nav_msgs/msg/Odometry'
    write_message_bag(path, types, run_metadata(run), messages())
    inputs = {'odom': ODOM_ENTRY}
    for a in actuators:
        inputs[a] = {'topic': f'/cmd/{a}', 'type': 'std_msgs/msg/Float64', 'actuator': a,
                     'unit': 'rad/s' if a == 'n_rpm' else 'rad'}
    return inputs


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """{form: (bag, input map path or None)} of one 60 s identification run of nps_auv2."""
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=60.0, seed=11)
    d = tmp_path_factory.mktemp('forms')
    out = {'default': (str(write_run_bag(run, d / 'default')), None)}
    for form, make in (('joints', _joint_bag), ('array', _array_bag), ('floats', _float_bag)):
        inputs = make(run, d / form)
        path = d / f'{form}.yaml'
        path.write_text(yaml.safe_dump({'version': 1, 'inputs': inputs}, sort_keys=False))
        out[form] = (str(d / form), str(path))
    return out


def _replay(bag, input_map):
    settings = IdentifierSettings.from_values(input_map=input_map)
    return replay_bag(bag, settings, warn=False)


@pytest.mark.parametrize('form, exact', [('joints', True), ('floats', True), ('array', False)])
def test_each_command_form_identifies_as_the_default_layout(bags, form, exact):
    ref = _replay(*bags['default'])
    got = _replay(*bags[form])
    assert got.accepted == ref.accepted > 1000 and got.rejected == ref.rejected == 0
    if exact:
        assert np.array_equal(got.estimate, ref.estimate)
        assert np.array_equal(got.cov, ref.cov)
        assert np.array_equal(got.U, ref.U)
    else:   # degrees and PWM: the inputs differ by rounding only
        assert np.allclose(got.U, ref.U, rtol=1e-12, atol=1e-12)
        assert np.allclose(got.estimate, ref.estimate, rtol=1e-6, atol=0)
    if form == 'floats':    # published on change: most actuators held most of the time
        counts = message_counts(bags[form][0])
        assert sum(n for t, n in counts.items() if t.startswith('/cmd/')) < 2 * ref.commands


def test_identify_bag_with_an_input_map_prints_the_default_layouts_figures(bags, capsys):
    def table(args):
        assert cli_main(['identify'] + args) == 0
        out = capsys.readouterr().out
        # all but the line naming the bag (and counting its command messages) and the timing
        return [ln for ln in out.splitlines() if 'wall' not in ln and 'from bag' not in ln]
    bag, path = bags['floats']
    assert table(['--bag', bag, '--input-map', path]) == table(['--bag', bags['default'][0]])


def test_a_map_naming_a_topic_the_bag_lacks_is_one_error(bags, tmp_path, capsys):
    bag, path = bags['joints']
    doc = yaml.safe_load(Path(path).read_text())
    doc['inputs']['fins']['topic'] = '/fins/cmd'
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump(doc))
    with pytest.raises(BagInputError) as info:
        _replay(bag, str(bad))
    assert isinstance(info.value, InputMapError)
    assert "no actuator topic '/fins/cmd' in the bag (input 'fins'" in str(info.value)
    # the default map on a bag of other topics names what it lacks
    with pytest.raises(BagInputError, match="no odometry topic '/odom'"):
        _replay(bag, None)
    assert cli_main(['identify', '--bag', bag, '--input-map', str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'/fins/cmd'" in err[0]
    # a joint the vehicle file has no actuator for
    doc['inputs']['fins']['channels'][0]['actuator'] = 'thruster_3'
    bad.write_text(yaml.safe_dump(doc))
    assert cli_main(['report', '--bag', bag, '--input-map', str(bad), '--out',
                     str(tmp_path / 'r')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'thruster_3' is no actuator of state.Input" in err[0]


@pytest.mark.parametrize('example', ['joint_names', 'stonefish_setpoints', 'per_fin_topics'])
def test_import_writes_the_bag_in_a_maps_layout(tmp_path, capsys, example):
    """import --input-map: a CSV log written as a bag in the topics and forms of a documented
    map (other joint names and a flipped sign, Float64MultiArray in degrees with a normalized
    shaft, per-actuator Float64 with PWM; ENU or NED odometry), replayed through the same map,
    gives what the default layout's import gives."""
    import csv

    from auv_ident.offline.importers import read_csv_run
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=30.0, seed=2)
    header = ['t', 'u', 'v', 'w', 'p', 'q', 'r', 'z', 'phi', 'theta', 'psi', 'dr', 'ds', 'db',
              'dbp', 'dbs', 'n']
    log = tmp_path / 'log.csv'
    with open(log, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for k, t in enumerate(run.t):
            w.writerow([f'{t:.2f}'] + [repr(float(run.y[k][i])) for i in
                                       (0, 1, 2, 3, 4, 5, 8, 9, 10, 11)]
                       + [repr(float(v)) for v in run.u[k][:6]])
    columns = {'time': {'column': 't', 'unit': 's'}}
    for q in ('u', 'v', 'w', 'p', 'q', 'r', 'z', 'phi', 'theta', 'psi'):
        columns[q] = {'column': q, 'unit': {'u': 'm/s', 'v': 'm/s', 'w': 'm/s', 'z': 'm'}.get(
            q, 'rad/s' if q in 'pqr' else 'rad')}
    for q, col in (('rudder', 'dr'), ('stern_planes', 'ds'), ('bow_planes', 'db'),
                   ('bow_plane_port', 'dbp'), ('bow_plane_starboard', 'dbs')):
        columns[q] = {'column': col, 'unit': 'rad'}
    columns['shaft'] = {'column': 'n', 'unit': 'rpm'}
    cmap = tmp_path / 'columns.yaml'
    cmap.write_text(yaml.safe_dump(columns))
    path = str(Path(__file__).resolve().parents[2] / 'docs' / 'examples' / f'{example}.yaml')
    base = ['import', '--format', 'csv', str(log), '--columns', str(cmap), '--vehicle',
            'nps_auv2']
    assert cli_main(base + ['--out', str(tmp_path / 'default')]) == 0
    assert cli_main(base + ['--out', str(tmp_path / 'mapped'), '--input-map', path]) == 0
    capsys.readouterr()
    imported = read_csv_run(log, cmap)
    ref = replay_bag(tmp_path / 'default', warn=False)
    got = _replay(str(tmp_path / 'mapped'), path)
    assert got.accepted == ref.accepted == len(imported.t_ns) and got.rejected == 0
    np.testing.assert_allclose(got.U, ref.U, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got.estimate, ref.estimate, rtol=1e-6)
    # the default map cannot read it: its topics are the example's
    with pytest.raises(BagInputError):
        replay_bag(tmp_path / 'mapped', warn=False)

"""metadata.yaml from whoever made the bag is read with bounds: YAML aliases ("billion laughs":
1 KB that grows without bound once its values become strings), an oversized file and
non-string custom_data values are one BagError naming the file, at once, in every reader
(bag info, reading the messages, repair, replay's custom data, the command line)."""
from pathlib import Path
import shutil
import subprocess
import sys

import helpers
import pytest

from auv_ident.bags.info import bag_info
from auv_ident.bags.reader import read_bag
from auv_ident.bags.repair import repair_bag
from auv_ident.bags.schema import BagError, bounded_yaml, MAX_METADATA_BYTES, qos_from_yaml
from auv_ident.offline.replay import bag_custom_data

SHIPPED = Path(helpers.REPO) / 'bags' / 'nps_auv2_ident'

LAUGHS = ('a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
          + ''.join(f'{c}: &{c} [' + ','.join([f'*{p}'] * 9) + ']\n'
                    for p, c in zip('abcdefgh', 'bcdefghi')))


def _bag_with_metadata(tmp_path, edit):
    bag = tmp_path / 'bag'
    shutil.copytree(SHIPPED, bag)
    meta = bag / 'metadata.yaml'
    meta.write_text(edit(meta.read_text(encoding='utf-8')), encoding='utf-8')
    return bag


def _with_laughs_in_custom_data(text):
    # the aliases defined at the top, one of them used as a custom_data value
    return LAUGHS + text.replace('  custom_data:\n', '  custom_data:\n    bomb: *i\n', 1)


def test_aliases_are_refused_before_they_expand():
    with pytest.raises(BagError, match=r'alias \*a'):
        bounded_yaml(LAUGHS, 'probe')
    assert bounded_yaml('a: [1, 2]\n', 'probe') == {'a': [1, 2]}


def test_a_laughs_metadata_is_one_error_in_every_reader(tmp_path):
    bag = _bag_with_metadata(tmp_path, _with_laughs_in_custom_data)
    assert 'custom_data:\n    bomb: *i' in (bag / 'metadata.yaml').read_text()
    for read in (bag_info, lambda b: list(read_bag(b))):
        with pytest.raises(BagError, match='metadata.yaml.*alias'):
            read(bag)
    assert bag_custom_data(bag) == {}
    with pytest.raises(BagError, match='metadata.yaml.*alias'):
        repair_bag(bag, out=tmp_path / 'repaired')
    r = subprocess.run([sys.executable, '-m', 'auv_ident', 'bag', 'info', str(bag)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count('\n') == 1 and 'alias' in r.stderr, r.stderr


def test_an_oversized_metadata_file_is_refused(tmp_path):
    bag = _bag_with_metadata(tmp_path, lambda t: t + '#' * (MAX_METADATA_BYTES + 1) + '\n')
    with pytest.raises(BagError, match='more than a rosbag2 metadata.yaml holds'):
        bag_info(bag)


def test_custom_data_values_must_be_strings(tmp_path):
    bag = _bag_with_metadata(tmp_path, lambda t: t.replace(
        '  custom_data:\n', '  custom_data:\n    nested: {a: 1}\n', 1))
    with pytest.raises(BagError, match="custom_data value of 'nested' is not a string"):
        bag_info(bag)
    plain = bag_info(SHIPPED).custom_data
    assert plain and all(isinstance(v, str) for v in plain.values())


def test_qos_yaml_with_aliases_is_refused():
    with pytest.raises(BagError, match='offered_qos_profiles.*alias'):
        qos_from_yaml('- &p {history: keep_last}\n- *p\n')

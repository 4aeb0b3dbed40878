"""core/safe_files.py: files written through a fresh temporary name and one rename, and the
private per-user folder, checked before use."""
import os
import stat

import pytest

from auv_ident.core import safe_files
from auv_ident.core.errors import ConfigError
from auv_ident.core.safe_files import private_dir, write_atomic


def test_write_atomic_follows_no_planted_symlink(tmp_path):
    """A symlink planted at the names a writer used to take (.<name>.<pid>.tmp) or anywhere
    beside the target redirects nothing: the victim stays as it was."""
    victim = tmp_path / 'victim'
    victim.write_text('precious')
    target = tmp_path / 'estimate.json'
    for name in (f'.{target.name}.{os.getpid()}.tmp', f'.{target.name}.tmp', 'estimate.json.tmp'):
        (tmp_path / name).symlink_to(victim)
    write_atomic(target, '{"a": 1}\n')
    assert victim.read_text() == 'precious'
    assert target.read_text() == '{"a": 1}\n' and not target.is_symlink()
    leftovers = {p.name for p in tmp_path.iterdir()} - {'victim', 'estimate.json'}
    assert all((tmp_path / n).is_symlink() for n in leftovers)   # only the planted links


def test_write_atomic_gives_the_umask_permissions_and_replaces_whole(tmp_path):
    target = tmp_path / 'out.csv'
    target.write_text('old')
    old = os.umask(0o027)
    try:
        write_atomic(target, b'new')
    finally:
        os.umask(old)
    assert target.read_bytes() == b'new'
    assert stat.S_IMODE(target.stat().st_mode) == 0o640


def test_private_dir_is_made_0700_and_checked(tmp_path, monkeypatch):
    monkeypatch.setenv('AUV_IDENT_CACHE', str(tmp_path / 'cache'))
    d = private_dir('vehicles', 'abc')
    assert d == tmp_path / 'cache' / 'vehicles' / 'abc'
    for level in (d, d.parent, d.parent.parent):
        assert stat.S_IMODE(level.stat().st_mode) == 0o700
    with pytest.raises(ConfigError, match='one plain name'):
        private_dir('vehicles', '..')


def test_a_planted_or_open_folder_is_passed_over_or_refused(tmp_path, monkeypatch):
    """A planted symlink or a folder open to others is never used: private_dir goes on to
    the next place, and names every refused one when none is left."""
    elsewhere = tmp_path / 'elsewhere'
    elsewhere.mkdir(mode=0o700)
    cache = tmp_path / 'cache'
    cache.mkdir(mode=0o700)
    (cache / 'vehicles').symlink_to(elsewhere)
    monkeypatch.setenv('AUV_IDENT_CACHE', str(cache))
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'xdg'))
    d = private_dir('vehicles')
    assert d == tmp_path / 'xdg' / 'auv_ident' / 'vehicles'      # the link passed over
    os.chmod(tmp_path / 'xdg' / 'auv_ident', 0o777)
    monkeypatch.setattr(safe_files, 'private_candidates',
                        lambda name: iter([str(cache / name),
                                           str(tmp_path / 'xdg' / 'auv_ident' / name)]))
    with pytest.raises(ConfigError, match='a symbolic link.*writable by other users'):
        private_dir('vehicles')

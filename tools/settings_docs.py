"""Write config/identifier.yaml and the docs/ros.md identifier parameter table from the
identifier settings' fields (auv_ident/session/settings.py).

    python tools/settings_docs.py           # write both
    python tools/settings_docs.py --check   # exit 1 if either is out of date
"""
import argparse
from pathlib import Path
import sys

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.session.settings_text import replace_docs_table, yaml_text  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--check', action='store_true', help='only check; exit 1 if out of date')
    args = ap.parse_args(argv)
    yaml_path, docs_path = REPO / 'config' / 'identifier.yaml', REPO / 'docs' / 'ros.md'
    wanted = {yaml_path: yaml_text(),
              docs_path: replace_docs_table(docs_path.read_text(encoding='utf-8'))}
    stale = [p for p, text in wanted.items() if p.read_text(encoding='utf-8') != text]
    if args.check:
        for p in stale:
            print(f'{p.relative_to(REPO)} is out of date: python tools/settings_docs.py')
        return 1 if stale else 0
    for p in stale:
        p.write_text(wanted[p], encoding='utf-8')
        print(f'wrote {p.relative_to(REPO)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""Command line: python -m auv_ident {simulate,identify,report,bag,import,derivatives,...}.

Expected errors (bad options, bad files, states outside the model's domain) print one clear
line on stderr and exit with status 2; no traceback. `identify` and `report` exit with status
EXIT_UNTRUSTED (3) when they computed a result that should not be trusted: NOT consistent (the
data contradict the identification's assumptions) or NOT plausible (the estimates contradict
the vehicle file or the physics); the first line of the output, result.json's `diagnosis`
and report.md say why.

The commands live by family, each module with its subcommands' options next to their code:
identify.py (simulate, identify, montecarlo, campaign), reports.py (report, compare-methods,
bench, export), data.py (bag, import, derivatives, vehicle check), glider.py (glider calibrate,
glider validate); common.py holds what they share. `run` (a node, as `ros2 run`) and
`loadtest` are handed over before argparse.
"""
import argparse
import sys

from auv_ident.cli import data, glider, identify, reports
from auv_ident.cli.common import EXIT_UNTRUSTED, option_name
from auv_ident.core.errors import AuvIdentError
from auv_ident.session.settings import ParameterError

__all__ = ['EXIT_UNTRUSTED', 'build_parser', 'main', 'run_node']

NODES = ('simulator', 'identifier', 'record', 'play')


def run_node(argv):
    """python -m auv_ident run NODE [--ros-args ...]: as `ros2 run auv_ident NODE`."""
    if not argv or argv[0] not in NODES:
        print(f'usage: python -m auv_ident run {{{",".join(NODES)}}} [--ros-args ...]',
              file=sys.stderr)
        return 2
    import importlib
    mod = importlib.import_module(f'auv_ident.ros.{argv[0]}_node')
    return mod.main([f'auv_ident_{argv[0]}'] + list(argv[1:])) or 0


def build_parser():
    p = argparse.ArgumentParser(prog='python -m auv_ident', description=__doc__.split('\n')[0])
    sub = p.add_subparsers(dest='cmd', required=True)
    for family in (identify, reports, data, glider):
        family.add_commands(sub)
    return p


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] == 'run':
        return run_node(argv[1:])
    if argv and argv[0] == 'loadtest':
        from auv_ident.ros.loadtest import main as loadtest_main
        return loadtest_main(argv[1:]) or 0
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ParameterError as err:      # an identifier setting: its option
        print(f'error: {option_name(err.name)}: {err.message}', file=sys.stderr)
        return 2
    except (AuvIdentError, OSError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130

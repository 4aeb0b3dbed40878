"""What every command family of the command line shares: the options made from the identifier
settings, the output checks (never replace a file silently), the trust exit status."""
import os

from auv_ident.core.errors import AuvIdentError

EXIT_UNTRUSTED = 3     # a result computed, but NOT consistent or NOT plausible (docstring)


def vehicle_model(args, theta_names=()):
    """The Model of --vehicle (and --mass-inverse), with ``theta_names`` free."""
    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.vehicles import load_vehicle
    return Model(load_vehicle(args.vehicle), theta_names,
                 mass_inverse=getattr(args, 'mass_inverse', 'default'))


def sim_current(text):
    """--current N,E[,D] of simulate: (3,) m/s NED, or None."""
    from auv_ident.core.model.current import parse_current
    if text is None:
        return None
    opt = parse_current(text, what='--current')
    if opt.estimate:
        raise AuvIdentError("simulate --current takes N,E[,D] in m/s (the water's velocity, "
                            'NED), not "estimate"')
    return opt.fixed


def progress_meter(label, total):
    """A progress bar on stderr (analysis/progress.py) of ``total`` steps."""
    from auv_ident.analysis.progress import Progress
    pr = Progress(total, label)
    return pr


def settings_of(args):
    """The IdentifierSettings of the options given (the rest: the defaults, or a bag's
    metadata where it says them)."""
    from auv_ident.session.settings import IdentifierSettings, settings_fields
    return IdentifierSettings.from_values(**{f.name: getattr(args, f.name, None)
                                             for f in settings_fields()})


def trust_status(doc):
    """0 for a result whose diagnosis says it can be trusted, else EXIT_UNTRUSTED."""
    diagnosis = doc.get('diagnosis') or {}
    trusted = diagnosis.get('consistent', True) and diagnosis.get('plausible', True)
    return 0 if trusted else EXIT_UNTRUSTED


def option_name(name):
    """The command-line option of a setting: noise_mode -> --noise-mode."""
    return '--' + name.replace('_', '-')


def check_outputs(args, *options, folder=False):
    """Before any work: each output option given (e.g. '--json') names a path that can be
    written, and one that exists is overwritten only with --force (a result, a model or a
    report is never replaced silently). folder: the outputs are folders (report --out)."""
    from auv_ident.core.safe_files import unwritable_reason
    for option in options:
        path = getattr(args, option.lstrip('-').replace('-', '_'), None)
        if not path:
            continue
        if os.path.lexists(path) and not args.force:
            raise AuvIdentError(f'{option} {path}: exists already; give --force to overwrite '
                                'it')
        reason = unwritable_reason(path, folder=folder)
        if reason:
            raise AuvIdentError(f'{option} {path}: {reason}')


def pct(v):
    """A fit % as printed: one decimal, '-' for none."""
    return '-' if v is None else f'{v:.1f}'


def vehicle_arg(sp):
    """--vehicle and --mass-inverse of a command that builds a model without the settings."""
    sp.add_argument('--vehicle', default='nps_auv2',
                    help='nps_auv2, remus100, isimi, or a vehicle YAML path')
    sp.add_argument('--mass-inverse', dest='mass_inverse', default='default',
                    choices=('default', 'exact', 'mss_literal'),
                    help="default: the vehicle file's choice (NPS AUV II: MSS literal)")


def force_arg(sp):
    """--force: what check_outputs lets replace."""
    sp.add_argument('--force', action='store_true',
                    help='overwrite an output that exists already (without it the command '
                         'stops at once, before any work, and says so)')


def scheduler_arg(sp):
    """--scheduler of the commands that run on Dask."""
    sp.add_argument('--scheduler', default=None, metavar='ADDRESS',
                    help='run on this existing Dask cluster (tcp://host:8786, or a '
                         'scheduler file) instead of a local one (docs/campaigns.md)')


def settings_args(sp, names=None):
    """An option for each identifier setting (or those named), made from its field:
    --name-with-dashes, help, choices, default (session/settings.py); lists are
    comma-separated. Not given: None (the default, or what a bag's metadata says)."""
    from auv_ident.session.settings import help_text, settings_fields
    for f in settings_fields():
        if names is not None and f.name not in names:
            continue
        kind, shown = f.metadata['kind'], f.default
        if isinstance(shown, tuple):
            shown = ','.join(map(str, shown)) or 'none'
        kw = {'dest': f.name, 'default': None,
              'help': (help_text(f) + f' (default: {shown})').replace('%', '%%')}
        if kind == 'bool':
            kw.update(action='store_const', const=True)
        elif f.metadata['choices']:
            kw['choices'] = f.metadata['choices']
        elif kind in ('strings', 'floats'):
            kw['metavar'] = 'A,B,...'
        elif kind == 'float':
            kw['type'] = float
        sp.add_argument(option_name(f.name), **kw)


def ident_args(sp):
    """What identify and montecarlo share beyond the settings."""
    sp.add_argument('--fixed-noise', dest='noise_mode', action='store_const', const='fixed',
                    help='same as --noise-mode fixed')
    sp.add_argument('--no-refine', action='store_true',
                    help='EKF pass only (no batch refinement)')
    sp.add_argument('--json', help='write the result as JSON')
    sp.add_argument('--rpm', type=float, default=None)
    force_arg(sp)

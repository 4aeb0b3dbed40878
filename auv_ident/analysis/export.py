"""The identified model written where users need it: ``python -m auv_ident export``.

Formats (docs/export.md):

- ``vehicle``: the vehicle file the model was identified with, the identified values in place.
  Each identified line keeps its place, its multiplier and the file's comment; it gains a
  comment with the 1-sigma, the file's old value and where the value came from. The file's
  ``prior:`` block gets each identified coefficient's 1-sigma as its absolute prior ``sd``, so
  that the next identification with this file judges a new run against this one
  (core/identification/plausibility.py). The vehicle's ``name`` is kept: it is the same vehicle,
  so bags that record it are identified with the new file without ``--other-vehicle``.

- ``uuv``: uuv_simulator's ``<hydrodynamic_model><type>fossen</type>`` xacro snippet, and
- ``gz``: the gz-sim Hydrodynamics system's ``<plugin>`` block (with ``<fluid_added_mass>`` or
  the plugin's *Dot* terms, ``gz_added_mass``): added mass exact, damping fitted
  (analysis/export_fossen.py), the fit % per DOF in the file's header and echoed;
- ``urdf-hydrodynamics``: the ``<hydrodynamics>`` URDF block of the ROS 2 ``hydrodynamics``
  library (auv_controllers), diagonal terms, fitted the same way;
- ``python``: a self-contained numpy module with our model written out term by term (exact;
  analysis/export_python.py).

The exported vehicle text is read back with the vehicle loader before it is written, and every
coefficient must come back as exported (identified: the estimate to the last bit; the others:
the file's value), else an ExportError: a file that loads differently is never written.
"""
import datetime
import json
import math
import os
from pathlib import Path
import re
import tempfile
import textwrap

import yaml

from auv_ident.analysis import export_fossen
from auv_ident.analysis.export_fossen import ExportError
from auv_ident.analysis.model_report import load_model
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.core.safe_files import write_atomic

FORMATS = ('vehicle', 'uuv', 'gz', 'urdf-hydrodynamics', 'python')
GZ_ADDED_MASS = ('link', 'plugin')
FITTED = ('uuv', 'gz', 'urdf-hydrodynamics')     # their damping is fitted (fit report)


def _number(value):
    """The shortest text that reads back as exactly this float (Python's repr)."""
    return repr(float(value))


def _sigma_text(sd):
    return 'unknown' if not math.isfinite(sd) else f'{sd:.3g}'


def _replace_value(lines, name, value, note):
    """Put ``value`` as the first element of the flow list ``NAME: [value, ...]`` under
    ``coefficients:`` and ``note`` before the line's own comment. Returns the old value text."""
    pattern = re.compile(r'^(\s+' + re.escape(name) + r'\s*:\s*\[\s*)([^,\]]+)(,[^\]]*\].*)$')
    in_coefficients = False
    for i, line in enumerate(lines):
        if re.match(r'^\S', line):
            in_coefficients = line.split('#')[0].strip() == 'coefficients:'
            continue
        m = pattern.match(line) if in_coefficients else None
        if m is None:
            continue
        head, old, tail = m.groups()
        body, sep, comment = tail.partition('#')
        text = f'{head}{_number(value)}{body.rstrip()}   # {note}'
        if sep:
            text += f'; {comment.strip()}'
        lines[i] = text
        return old.strip()
    raise ExportError(f'coefficient {name}: no line "{name}: [value, equation, k, multiplier]" '
                      'under coefficients: in the vehicle file; the exporter edits that form')


def _top_level_blocks(lines):
    """{key: (first, end)} line ranges of the file's top-level keys (comments above a key
    belong to the block before it)."""
    starts = [(i, line.split(':', 1)[0].strip()) for i, line in enumerate(lines)
              if re.match(r'^[A-Za-z_]\w*\s*:', line)]
    return {key: (i, starts[j + 1][0] if j + 1 < len(starts) else len(lines))
            for j, (i, key) in enumerate(starts)}


def _with_prior(lines, raw, model):
    """The lines with a ``prior:`` block that holds the file's prior and, per identified
    coefficient, the identified 1-sigma as its absolute sd."""
    prior = dict(raw.get('prior') or {})
    per = dict(prior.get('coefficients') or {})
    for name, sd in zip(model.names, model.std):
        if math.isfinite(sd) and sd > 0:
            per[name] = {'sd': float(sd)}
    if not per:
        return lines
    prior['coefficients'] = per
    block = ['# prior of the next identification: the identified 1-sigma of each identified '
             'coefficient (auv_ident export)']
    block += yaml.safe_dump({'prior': prior}, sort_keys=False,
                            default_flow_style=None).rstrip('\n').splitlines()
    blocks = _top_level_blocks(lines)
    if 'prior' in blocks:
        first, end = blocks['prior']
        return lines[:first] + block + lines[end:]
    return lines + [''] + block


def _runs(model):
    return ', '.join(model.bags) or model.source or model.path


def _header(model):
    day = datetime.date.today().isoformat()
    return [f'# Exported by `python -m auv_ident export` on {day} from {model.path}',
            f'# (identified from {_runs(model)}).',
            f'# Identified: {", ".join(model.names)}; each such line says its 1-sigma and the',
            '# value this file had, and the prior: block holds the 1-sigmas. Everything else',
            '# is the original file.']


def _set_top_level(lines, key, value_text):
    """Replace the one-line top-level ``key:`` (keeping its comment), or add it."""
    blocks = _top_level_blocks(lines)
    if key in blocks:
        first, _ = blocks[key]
        _, sep, comment = lines[first].partition('#')
        lines[first] = f'{key}: {value_text}' + (f'   # {comment.strip()}' if sep else '')
    else:
        lines.append(f'{key}: {value_text}')


def vehicle_text(model):
    """The exported vehicle file's text (see the module docstring); ``model`` : SavedModel."""
    vehicle = model.vehicle
    try:
        text = Path(vehicle.path).read_text(encoding='utf-8')
    except OSError as exc:
        raise ExportError(f'{vehicle.path}: cannot read the vehicle file: {exc}') from None
    lines = text.splitlines()
    for name, value, sd in zip(model.names, model.estimate, model.std):
        old = vehicle.coefficients[vehicle.index(name)].value
        _replace_value(lines, name, value,
                       f'identified, 1-sigma {_sigma_text(sd)}; file value '
                       f'{_number(old)}')
    lines = _with_prior(lines, vehicle.raw, model)
    title = f'{vehicle.title} (identified: {", ".join(model.names)})'
    _set_top_level(lines, 'title', yaml.safe_dump(title, default_style='"').strip())
    if model.mass_inverse not in ('default', vehicle.raw.get('mass_inverse', 'default')):
        # the identification formed M^-1 otherwise than the file says: the file must too, or
        # it is another model
        _set_top_level(lines, 'mass_inverse', model.mass_inverse)
    return '\n'.join(_header(model) + lines) + '\n'


def _check_reads_back(path, model):
    """ExportError unless the written vehicle file loads with every value as exported."""
    try:
        back = vehicle_from_file(str(path))
    except ConfigError as exc:
        raise ExportError(f'the exported vehicle file does not load: {exc}') from None
    want = dict(zip(vehicle_names := model.vehicle.names, model.vehicle.values))
    want.update(zip(model.names, model.estimate))
    got = dict(zip(back.names, back.values))
    if back.names != vehicle_names:
        raise ExportError(f'{path}: the exported file has coefficients {back.names}, the '
                          f'original {vehicle_names}')
    wrong = [n for n in vehicle_names if got[n] != want[n]]
    if wrong:
        raise ExportError(f'{path}: the exported file reads back other values for '
                          f'{", ".join(wrong)}')


def _fossen_header(model, parts):
    day = datetime.date.today().isoformat()
    return [f'Exported by `python -m auv_ident export` on {day} from {model.path}',
            f'(identified from {_runs(model)}; vehicle {model.vehicle.name}).',
            "Added mass: exactly our M_A. Damping: fitted by least squares to our model's",
            'hydrodynamic force on the velocities (all but rigid body, added-mass inertia and',
            'Coriolis, restoring, fins and propulsion) over the envelope of',
            *textwrap.wrap(parts.run_name, 88),
            f'and {export_fossen.N_BOX} uniform points in the box of those velocities',
            '(analysis/export_fossen.py): terms the target cannot hold (cross-flow integrals,',
            'fin lift, speed-scaled terms) are approximated.']


def _fossen_text(model, fmt, gz_added_mass, echo, bags=None):
    """(text, fit % (6,), parts) of a fitted format."""
    parts = export_fossen.fossen_parts(model, bags=bags)
    header = _fossen_header(model, parts)
    if fmt == 'uuv':
        text, fit = export_fossen.uuv_text(model, parts, header)
    elif fmt == 'gz':
        text, fit = export_fossen.gz_text(model, parts, header, gz_added_mass)
    else:
        text, fit = export_fossen.hydrodynamics_text(model, parts, header)
    if echo is not None:
        echo(f'fit envelope: {parts.run_name}')
        for line in export_fossen.fit_lines(fit, f'the {fmt} damping'):
            echo(line)
    return text, fit, parts


def fit_path(out):
    """Where the fit report of a fitted export goes by default: next to the file."""
    return Path(str(out) + '.fit.json')


def _fit_report(fmt, out, fit, parts):
    return json.dumps({
        'format': fmt, 'file': str(out),
        'fit_percent': {d: (round(float(f), 4) if math.isfinite(f) else None)
                        for d, f in zip(export_fossen.DOF, fit)},
        'fit_goal_percent': export_fossen.FIT_GOAL,
        'below_goal': [d for d, f in zip(export_fossen.DOF, fit)
                       if math.isfinite(f) and f < export_fossen.FIT_GOAL],
        'not_excited': [d for d, f in zip(export_fossen.DOF, fit) if not math.isfinite(f)],
        'envelope': parts.run_name, 'bags': parts.bags, 'samples': int(len(parts.nu)),
        'definition': '100 (1 - |H - H_target| / |H - mean H|) per DOF over the samples '
                      '(docs/export.md)'}, indent=1) + '\n'


def export_model(model_path, out, fmt='vehicle', vehicle=None, gz_added_mass='link',
                 echo=None, bags=None, fit_out=None):
    """Write the model of ``model_path`` (an ``identify --json``/``report`` result.json or the
    identifier node's estimate file) to ``out`` in format ``fmt``. Returns the path written.

    ``vehicle``: the vehicle file or name the model was identified with (default: the one the
    model file names). ``out`` is replaced if it exists (the command refuses that without
    --force, cli._check_outputs, as for every output). ``gz_added_mass``:
    'link' or 'plugin' (format gz). ``echo``: called with each fit line (fitted formats).
    Fitted formats (uuv, gz, urdf-hydrodynamics): ``bags`` the runs whose measured velocities
    are the fit's envelope (None: the model's own bags when they are here, else a simulated
    run); the fit % per DOF is written to ``fit_out`` (default fit_path(out), next to the
    file) as JSON."""
    if fmt not in FORMATS:
        raise ExportError(f'--format {fmt!r}: use one of {", ".join(FORMATS)}')
    if gz_added_mass not in GZ_ADDED_MASS:
        raise ExportError(f'--gz-added-mass {gz_added_mass!r}: use one of '
                          f'{", ".join(GZ_ADDED_MASS)}')
    out = Path(out)
    model = load_model(model_path, vehicle=vehicle)
    if fmt != 'vehicle':
        report = None
        if fmt == 'python':
            from auv_ident.analysis.export_python import python_text
            text = python_text(model)
        else:
            text, fit, parts = _fossen_text(model, fmt, gz_added_mass, echo, bags)
            report = _fit_report(fmt, out, fit, parts)
        try:
            path = write_atomic(out, text)
            if report is not None:
                where = write_atomic(Path(fit_out) if fit_out else fit_path(out), report)
                if echo is not None:
                    echo(f'wrote the fit report {where}')
            return path
        except OSError as exc:
            raise ExportError(f'{out}: cannot write: {exc}') from None
    text = vehicle_text(model)
    try:
        fd, draft = tempfile.mkstemp(dir=out.parent, prefix=f'.{out.name}.', suffix='.yaml')
        try:
            with os.fdopen(fd, 'w', encoding='utf-8') as fh:
                fh.write(text)
            _check_reads_back(draft, model)
        finally:
            os.unlink(draft)
        return write_atomic(out, text)
    except OSError as exc:
        raise ExportError(f'{out}: cannot write: {exc}') from None


# report --export FORMAT: the file each format gets in the report folder
REPORT_FILES = {'vehicle': 'vehicle.yaml', 'uuv': 'uuv.xacro', 'gz': 'gz.sdf',
                'urdf-hydrodynamics': 'hydrodynamics.urdf', 'python': 'model.py'}


def check_formats(formats):
    """ExportError naming a format that is not one of FORMATS (before a long report)."""
    for fmt in formats:
        if fmt not in FORMATS:
            raise ExportError(f'--export {fmt!r}: use one of {", ".join(FORMATS)}')


def export_into(folder, model_path, formats, vehicle=None, bags=None, echo=None):
    """``report --export FORMAT ...``: the report's model exported into its folder, one file
    per format named by REPORT_FILES (fitted formats with their fit report next to it).
    Returns the paths written."""
    check_formats(formats)
    return [export_model(model_path, Path(folder) / REPORT_FILES[fmt], fmt=fmt,
                         vehicle=vehicle, echo=echo, bags=bags)
            for fmt in dict.fromkeys(formats)]

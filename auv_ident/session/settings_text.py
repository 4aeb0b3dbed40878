"""The identifier's parameter file (config/identifier.yaml) and the docs/ros.md parameter
table, made from the fields of :class:`~auv_ident.session.settings.IdentifierSettings`.

``python tools/settings_docs.py`` writes both; test/session/test_settings_agree.py checks them,
the node's declarations and the command-line options against the fields."""
import textwrap

from auv_ident.session.settings import help_text, settings_fields

YAML_HEAD = """\
# Parameters of the identifier node (auv_ident/ros/identifier_node.py): every identifier
# setting (auv_ident/session/settings.py, IdentifierSettings), then the node's save_path.
# Written by tools/settings_docs.py from the settings' fields: edit those, not this file.
#   ros2 run auv_ident identifier --ros-args --params-file config/identifier.yaml
#   python -m auv_ident run identifier --ros-args --params-file config/identifier.yaml
# Write floats as floats (10.0, not 10): a double parameter rejects an integer value.
# An empty list ([]) means "not set", i.e. the documented default.
# The section name must match the node name ('identifier'; '/**' matches any node).
identifier:
  ros__parameters:
"""
# the identifier node's own parameter (not an identification setting; ros/identifier_node.py
# declares it from here): name, default, description
SAVE_PATH = ('save_path', '', 'estimate JSON written on ~/save, on shutdown and every 10 s; '
                              'empty = none; its folder must exist and be writable (checked '
                              'at start-up: exit 2), a failed save at shutdown exits 2')
INDENT = '    '


def yaml_value(value):
    """A setting's value as a ROS parameter file writes it (floats with a dot: a YAML 1.1
    reader takes 1e-05 for text; list entries quoted: a bare y is a YAML boolean)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        text = repr(value)
        if 'e' in text and '.' not in text:
            mantissa, exponent = text.split('e')
            text = f'{mantissa}.0e{exponent}'
        return text
    if isinstance(value, tuple):
        return '[' + ', '.join(f"'{v}'" if isinstance(v, str) else yaml_value(v)
                               for v in value) + ']'
    return value if value else "''"


def yaml_text():
    """config/identifier.yaml: each setting with its help, unit, choices and note as a
    comment, set to its default."""
    out = [YAML_HEAD]
    for f in settings_fields():
        comment = help_text(f) + '.' + (' ' + f.metadata['note'] if f.metadata['note'] else '')
        out += [INDENT + '# ' + line + '\n'
                for line in textwrap.wrap(comment, 99 - len(INDENT) - 2)]
        out.append(f'{INDENT}{f.name}: {yaml_value(f.default)}\n')
    name, default, text = SAVE_PATH
    out += [f'{INDENT}# {text}.\n', f'{INDENT}{name}: {yaml_value(default)}\n']
    return ''.join(out)


def docs_default(f):
    """A setting's default as the docs table shows it."""
    return f'`{yaml_value(f.default)}`'


def docs_cell(text):
    """Text in a Markdown table cell ('|' would end the cell, '<name>' read as HTML)."""
    return text.replace('|', '\\|').replace('<', '\\<')


def docs_rows():
    """The rows of the docs/ros.md identifier parameter table (header included)."""
    rows = ['| parameter | default | meaning |', '|---|---|---|']
    rows += [f'| `{f.name}` | {docs_default(f)} | {docs_cell(help_text(f))} |'
             for f in settings_fields()]
    name, default, text = SAVE_PATH
    rows.append(f'| `{name}` | `{yaml_value(default)}` | {docs_cell(text)} |')
    return rows


def replace_docs_table(markdown):
    """docs/ros.md with its identifier parameter table (the table after '## identifier')
    made again."""
    head, sep, rest = markdown.partition('\n## identifier\n')
    if not sep:
        raise ValueError("docs/ros.md has no '## identifier' section")
    lines = rest.split('\n')
    start = next(i for i, line in enumerate(lines) if line.startswith('| parameter |'))
    end = start
    while end < len(lines) and lines[end].startswith('|'):
        end += 1
    return head + sep + '\n'.join(lines[:start] + docs_rows() + lines[end:])

"""The report as one self-contained HTML file (report.html beside report.md), to be mailed.

Rendered from the report's own Markdown, so the two never disagree. Only the subset the report
writes is understood: ``#``..``####`` headings, paragraphs, ``- `` lists, pipe tables,
``![caption](file.png)`` images, ``*italic*``, ``**bold**``, ```code``` spans and fenced code
blocks. Images are embedded as base64 ``data:image/png`` URIs; links become their text. The
page loads nothing from anywhere (no external src or href), so it reads the same offline.
"""
import base64
import html
import os
import re

_IMAGE = re.compile(r'^!\[(?P<alt>[^\]]*)\]\((?P<src>[^)\s]+)\)$')
_LINK = re.compile(r'(?<!!)\[(?P<text>[^\]]+)\]\([^)]*\)')
_CODE = re.compile(r'`([^`]+)`')
_BOLD = re.compile(r'\*\*(.+?)\*\*')
_ITALIC = re.compile(r'(?<![\w*])\*(?!\s)([^*]+?)\*(?![\w*])')

STYLE = """
body { font-family: sans-serif; max-width: 70em; margin: 1em auto; padding: 0 1em;
       color: #222; line-height: 1.4; }
table { border-collapse: collapse; margin: 0.5em 0 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; }
th { background: #eee; }
td:first-child, th:first-child { text-align: left; }
img { max-width: 100%; height: auto; }
code, pre { background: #f4f4f4; }
pre { padding: 0.5em; overflow-x: auto; }
"""


def _inline(text):
    """Escaped HTML of one line's inline Markdown (code spans are left verbatim)."""
    parts = re.split(r'(`[^`]+`)', text)
    out = []
    for part in parts:
        if len(part) > 1 and part.startswith('`') and part.endswith('`'):
            out.append(f'<code>{html.escape(part[1:-1])}</code>')
            continue
        part = _LINK.sub(lambda m: m.group('text'), part)
        part = html.escape(part, quote=False)
        part = _BOLD.sub(r'<strong>\1</strong>', part)
        part = _ITALIC.sub(r'<em>\1</em>', part)
        out.append(part)
    return ''.join(out)


def _data_uri(src, base_dir):
    """The image file src (relative to base_dir) as a data: URI; ValueError if it is not a
    local PNG (nothing external may be referenced)."""
    path = src if os.path.isabs(src) else os.path.join(base_dir, src)
    with open(path, 'rb') as fh:
        data = fh.read()
    if not data.startswith(b'\x89PNG\r\n\x1a\n'):
        raise ValueError(f'{path}: not a PNG image')
    return 'data:image/png;base64,' + base64.b64encode(data).decode('ascii')


def _cells(line):
    return [c.strip() for c in line.strip().strip('|').split('|')]


def markdown_to_html(md, base_dir, title=None):
    """The full HTML document of the report's Markdown `md`; images read from base_dir."""
    lines = md.splitlines()
    body = []
    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if not stripped:
            i += 1
            continue
        if stripped.startswith('```'):
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith('```'):
                j += 1
            body.append('<pre><code>' + html.escape('\n'.join(lines[i + 1:j])) + '</code></pre>')
            i = j + 1
            continue
        m = re.match(r'^(#{1,4})\s+(.*)$', stripped)
        if m:
            level = len(m.group(1))
            if title is None and level == 1:
                title = m.group(2)
            body.append(f'<h{level}>{_inline(m.group(2))}</h{level}>')
            i += 1
            continue
        img = _IMAGE.match(stripped)
        if img:
            alt = html.escape(img.group('alt'))
            body.append(f'<figure><img src="{_data_uri(img.group("src"), base_dir)}" '
                        f'alt="{alt}"></figure>')
            i += 1
            continue
        if stripped.startswith('|'):
            rows = []
            while i < len(lines) and lines[i].strip().startswith('|'):
                rows.append(_cells(lines[i]))
                i += 1
            head, rest = rows[0], [r for r in rows[1:]
                                   if not all(re.fullmatch(r':?-+:?', c) for c in r)]
            out = ['<table>', '<thead><tr>' + ''.join(f'<th>{_inline(c)}</th>' for c in head)
                   + '</tr></thead>', '<tbody>']
            out += ['<tr>' + ''.join(f'<td>{_inline(c)}</td>' for c in r) + '</tr>'
                    for r in rest]
            body.append('\n'.join(out + ['</tbody>', '</table>']))
            continue
        if stripped.startswith('- '):
            items = []
            while i < len(lines) and lines[i].strip().startswith('- '):
                item = lines[i].strip()[2:]
                i += 1
                while (i < len(lines) and lines[i].startswith('  ') and lines[i].strip()
                       and not lines[i].strip().startswith('- ')):
                    item += ' ' + lines[i].strip()     # a continued item
                    i += 1
                items.append(f'<li>{_inline(item)}</li>')
            body.append('<ul>\n' + '\n'.join(items) + '\n</ul>')
            continue
        para = [stripped]
        i += 1
        while i < len(lines) and lines[i].strip() and not re.match(
                r'^(#{1,4}\s|\||- |```|!\[)', lines[i].strip()):
            para.append(lines[i].strip())
            i += 1
        body.append('<p>' + _inline(' '.join(para)) + '</p>')
    title = title or 'Identification report'
    return ('<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<title>{html.escape(title)}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n'
            + '\n'.join(body) + '\n</body>\n</html>\n')


def write_html(md, base_dir, path):
    """Write markdown_to_html(md, base_dir) to path; returns path."""
    with open(path, 'w', encoding='utf-8') as fh:
        fh.write(markdown_to_html(md, base_dir))
    return path

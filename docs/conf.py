"""Sphinx configuration of the docs site (`make docs`: docs/_build/html, warnings are errors).

The pages are the Markdown files of docs/ (MyST); the API reference (docs/api/) is autodoc of the
public modules' docstrings. autodoc imports the modules: the ROS parts import rclpy and the message
packages only inside functions (docs/DESIGN.md, the layer rule), and those imports are mocked so
that a build never starts ROS.
"""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

project = 'formation'
author = 'the formation project'
copyright = 'the formation project'

extensions = ['myst_parser', 'sphinx.ext.autodoc']
source_suffix = {'.md': 'markdown'}
root_doc = 'index'
exclude_patterns = ['_build', 'figures/*.md']
# MyST: anchors for '#'-links to headings down to ###, as GitHub makes them.
myst_heading_anchors = 4
myst_enable_extensions = ['colon_fence', 'dollarmath']

html_theme = 'furo'
html_title = 'formation: event-triggered formation control on ROS 2'
html_static_path: list[str] = []

autodoc_default_options = {'members': True, 'undoc-members': False, 'show-inheritance': False}
autodoc_member_order = 'bysource'
autodoc_typehints = 'description'
autodoc_mock_imports = [
    'rclpy',
    'std_msgs',
    'std_srvs',
    'geometry_msgs',
    'rosgraph_msgs',
    'visualization_msgs',
    'nav_msgs',
    'builtin_interfaces',
    'rcl_interfaces',
]
# The docstrings are prose with `code` in single backticks: show it as code, not as references.
default_role = 'code'
nitpicky = False
suppress_warnings = ['myst.header']


# The docstrings are written to be read as plain text (and cite the paper's labels, norms as
# ||x|| or |x|, Markdown ``` fences): made into reStructuredText here, before autodoc parses them,
# rather than rewritten in the sources.
_LIST_ITEM = re.compile(r'\s*([-*+]|\d+[.)]) ')
_PIPE = re.compile(r'(?<!\\)\|')


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(' '))


def _escape(line: str) -> str:
    """`|` (a substitution in reST) escaped outside `code`; a letter glued to a literal set apart."""
    parts = line.split('`')
    for k in range(0, len(parts), 2):  # the text between literals
        parts[k] = _PIPE.sub(r'\\|', parts[k])
        if k > 0 and parts[k][:1].isalnum():  # `Case`s: reST wants no letter right after a literal
            parts[k] = '\\ ' + parts[k]
    return '`'.join(parts)


def rest_lines(lines: list[str]) -> list[str]:
    """Docstring lines as reST: ``` fences as code blocks, `|` escaped, a line indented deeper than
    the one before it (a wrapped sentence) joined to its paragraph, a blank line before a list."""
    out: list[str] = []
    fence: int | None = None
    literal: int | None = None  # an indented block after a blank line: kept as it is
    previous = ''
    last = ''  # the last non-blank line
    for line in lines:
        stripped = line.strip()
        if literal is not None and (not stripped or _indent(line) >= literal):
            out.append(line)
            continue
        literal = None
        indented = stripped and not previous and last and _indent(line) >= _indent(last) + 4
        if indented and not _LIST_ITEM.match(last) and fence is None:
            literal = _indent(line)
            out += ['', '::', '', line]
            last = line
            continue
        if stripped.startswith('```'):
            if fence is None:
                fence = _indent(line)
                language = stripped[3:].strip() or 'text'
                out += ['', ' ' * fence + f'.. code-block:: {language}', '']
            else:
                fence = None
                out.append('')
            previous = ''
            continue
        if fence is not None:
            out.append(' ' * (fence + 4) + line[fence:] if stripped else '')
            continue
        if stripped and previous.strip():
            starts_list = _LIST_ITEM.match(line) and not _LIST_ITEM.match(previous)
            deeper = _indent(line) > _indent(previous)
            if starts_list and _indent(line) <= _indent(previous):
                out.append('')
            elif deeper and not _LIST_ITEM.match(previous) and not previous.rstrip().endswith('::'):
                line = ' ' * _indent(previous) + stripped
            elif deeper and _LIST_ITEM.match(previous):
                item = _LIST_ITEM.match(previous)
                line = ' ' * (_indent(previous) + len(item.group(0)) - _indent(previous)) + stripped
        out.append(_escape(line) if stripped else '')
        previous = line if stripped else ''
        last = line if stripped else last
    return out


def _process_docstring(app, what, name, obj, options, lines):
    lines[:] = rest_lines(lines)


def setup(app):
    app.connect('autodoc-process-docstring', _process_docstring)

"""
The README stays short and points at the pages; the pages name real files.

The README is what the package does, the two commands, how to install,
the nodes at a glance and where each guide lives; the file layout is
explained by the design page (layers and data path), whose layer table
names every subpackage. Every repository path the README or a page
names in backticks exists (``NAME`` in a path is a placeholder).
"""

import re

from conftest import REPO

DOC = REPO / 'doc'
PAGES = [REPO / 'README.md'] + sorted(DOC.glob('*.md'))
COMMANDS = ('bash scripts/demo.sh '
            '../shared/datasets/ujiindoorloc/validationData-public.csv',
            'bash scripts/test.sh')
PACKAGE = REPO / 'wifi_place_recognition'
#: Where a relative path in the pages may start: the repository, the
#: package (``core/tracking.py``), the benchmarks (``results/node.json``).
ROOTS = (REPO, PACKAGE, REPO / 'benchmarks')
TOP = {p.name for root in ROOTS for p in root.iterdir()}


def test_readme_is_short_with_one_picture_and_the_two_commands():
    text = (REPO / 'README.md').read_text()
    assert len(text.splitlines()) <= 200
    assert len(re.findall(r'!\[[^\]]*\]\(([^)]+)\)', text)) == 1
    lines = [line.strip() for line in text.splitlines()]
    for command in COMMANDS:
        assert command in lines, command
    assert COMMANDS[1] in (REPO / '.ci' / 'run').read_text()


def test_readme_links_every_guide_and_every_link_resolves():
    text = (REPO / 'README.md').read_text()
    links = re.findall(r'\]\(([^)#\s]+)(?:#[^)]*)?\)', text)
    local = [link for link in links if '://' not in link]
    assert [link for link in local if not (REPO / link).exists()] == []
    guides = {f'doc/{p.name}' for p in DOC.glob('*.md')}
    assert sorted(guides - set(local)) == []


def test_design_page_names_every_subpackage():
    design = (DOC / 'design.md').read_text()
    layers = design.split('\n## Layers\n', 1)[1].split('\n## ', 1)[0]
    subpackages = {p.parent.name for p in PACKAGE.glob('*/__init__.py')}
    named = set(re.findall(r'^\| `(\w+)/` \|', layers, re.M))
    assert named == subpackages


def _paths(text):
    """Return the repository-looking paths in backticks of a page."""
    found = set()
    for token in re.findall(r'`([^`\s]+)`', text):
        token = token.rstrip('/')
        if '/' in token and re.fullmatch(r'[\w.-]+(/[\w.-]+)+', token) \
                and token.split('/')[0] in TOP and 'NAME' not in token:
            found.add(token)
    return found


def test_paths_named_in_the_pages_exist():
    missing = [(page.name, path) for page in PAGES
               for path in sorted(_paths(page.read_text()))
               if not any((root / path).exists() for root in ROOTS)]
    assert missing == []

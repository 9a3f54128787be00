"""
The documentation: the site builds, its examples run, its files exist.

- ``doc/`` builds with Sphinx (MyST pages, autodoc API pages) with
  warnings as errors: a broken link or anchor, a missing page or picture,
  a docstring that no longer parses fails;
- every module of ``core``, ``data`` and ``training`` has an API entry;
- the pages fit the text column of both themes: no code line in a page
  longer than the default theme shows without scrolling, and the style
  that makes rosdoc2's table cells wrap is wired into ``conf.py``;
- the shell examples the pages mark runnable (an HTML comment
  ``<!-- runnable -->`` on the line before a ``sh`` block: needs no
  hardware and no ``ros2`` CLI) are taken from README.md and doc/*.md and
  run as written, from the repository, with the venv's executables on
  PATH and a fresh home folder;
- ``benchmarks/results/README.md`` lists every result file, and the pages
  it names cite it; the pictures are those ``benchmarks/figures.py``
  draws from the committed JSON.
"""

import json
import os
from pathlib import Path
import re
import sys

from conftest import REPO, run
import pytest

DOC = REPO / 'doc'
PAGES = [REPO / 'README.md'] + sorted(DOC.glob('*.md'))
RESULTS = REPO / 'benchmarks' / 'results'
MARKER = '<!-- runnable -->'
#: The datasets the examples name, beside the repository as in CI.
EXAMPLE_DATA = REPO.parent / 'shared' / 'datasets'
BLOCK = re.compile(r'^```(\w*)\n(.*?)^```$', re.M | re.S)
#: The longest code line the default theme (alabaster) shows in its text
#: column without a scroll bar; rosdoc2's column holds more.
CODE_WIDTH = 66
#: The style both themes load (conf.py): table cells wrap, long code
#: names in them break.
STYLE = DOC / '_static' / 'readable.css'


def examples():
    """Return [(page:line, shell text)] of the blocks marked runnable."""
    found = []
    for page in PAGES:
        text = page.read_text()
        for block in BLOCK.finditer(text):
            before = text[:block.start()].rstrip('\n').rsplit('\n', 1)[-1]
            if before.strip() == MARKER:
                line = text[:block.start()].count('\n') + 1
                found.append((f'{page.relative_to(REPO)}:{line}',
                              block.group(1), block.group(2)))
    return found


def test_runnable_examples_are_found_and_are_shell():
    found = examples()
    markers = sum(p.read_text().count(MARKER) for p in PAGES)
    assert len(found) == markers, 'a runnable marker not before a block'
    assert [where for where, lang, _ in found if lang != 'sh'] == []
    pages = {where.split(':')[0] for where, _, _ in found}
    assert {'README.md', 'doc/start-here.md', 'doc/training.md',
            'doc/your-building.md'} <= pages


@pytest.mark.parametrize('where,lang,script', examples(),
                         ids=[e[0] for e in examples()])
def test_runnable_example_works_as_written(where, lang, script, tmp_path):
    for path in re.findall(r'\.\./shared/datasets/[\w./-]+', script):
        if not (REPO / path).exists():
            pytest.skip(f'{path} not here ({EXAMPLE_DATA} absent)')
    home = tmp_path / 'home'
    home.mkdir()
    env = dict(os.environ, HOME=str(home), PATH=os.pathsep.join(
        [str(Path(sys.executable).parent), os.environ['PATH']]))
    out = run(['bash', '-euo', 'pipefail', '-c', script], cwd=REPO,
              env=env, timeout=600)
    assert out.returncode == 0, f'{where}\n{script}\n{out.stdout[-3000:]}' \
        f'\n{out.stderr[-3000:]}'


def code_lines(page):
    """Return [(line number, line)] inside the page's fenced code blocks."""
    found, fence = [], None
    for number, line in enumerate(page.read_text().splitlines(), 1):
        if fence is None:
            opening = re.match(r'(`{3,}|~{3,})(.*)', line)
            if opening:    # a MyST directive ({toctree}) is no code
                fence = opening.group(1)
                code = not opening.group(2).strip().startswith('{')
        elif line.strip().startswith(fence) and \
                line.strip().strip(fence[0]) == '':
            fence = None
        elif code:
            found.append((number, line))
    return found


def test_code_lines_fit_the_default_themes_column():
    pages = sorted(DOC.rglob('*.md'))
    long = [f'{page.relative_to(REPO)}:{number}: {line}'
            for page in pages for number, line in code_lines(page)
            if len(line) > CODE_WIDTH]
    assert not long, f'wrap under {CODE_WIDTH} characters (shell: a ' \
        'backslash continuation):\n' + '\n'.join(long)


def _conf(path):
    """Return the settings conf.py gives when ``path`` is run."""
    out = run([sys.executable, '-c', 'import json, runpy; s = runpy.run_path('
               f'"{path}"); print(json.dumps([s.get("html_static_path"), '
               's.get("html_css_files")]))'])
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_both_themes_load_the_style_that_fits_the_column(tmp_path):
    wrapper = tmp_path / 'wrapped_sphinx_directory' / 'conf.py'
    wrapper.parent.mkdir()
    wrapper.write_text(f'exec(open("{DOC / "conf.py"}").read())\n')
    for conf in (DOC / 'conf.py', wrapper):    # Sphinx's, rosdoc2's
        static, css = _conf(conf)
        assert css == [STYLE.name] and static, conf
        assert [Path(conf.parent, f) / STYLE.name for f in static] == \
            [STYLE], conf
    style = re.sub(r'\s+', ' ', STYLE.read_text())
    # rosdoc2's theme keeps every cell on one line (white-space: nowrap)
    assert '.wy-table-responsive table td, .wy-table-responsive table th' \
        in style and 'white-space: normal' in style


def test_site_builds_with_warnings_as_errors(tmp_path):
    out = run([sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q',
               '-b', 'html', '-d', str(tmp_path / 'doctrees'), str(DOC),
               str(tmp_path / 'html')], cwd=REPO)
    assert out.returncode == 0, out.stdout + out.stderr
    assert (tmp_path / 'html' / 'api' / 'core.html').exists()
    assert _loads_the_style(tmp_path / 'html', 'design.html')


def test_rosdoc2_builds_the_site_without_warnings(tmp_path):
    # as docs.ros.org builds a package: the pages, the API and the README
    env = dict(os.environ, PATH=os.pathsep.join(
        [str(Path(sys.executable).parent), os.environ['PATH']]))
    out = run(['rosdoc2', 'build', '--package-path', REPO, '-o',
               tmp_path / 'out', '-d', tmp_path / 'build', '-c',
               tmp_path / 'cross_reference'], env=env)
    log = out.stdout + out.stderr
    assert out.returncode == 0 and 'WARNING' not in log, log[-5000:]
    site = tmp_path / 'out' / 'wifi_place_recognition'
    assert 'class wifi_place_recognition.core.recognizer.PlaceRecognizer' in \
        re.sub(r'<[^>]+>', '', (site / 'api' / 'core.html').read_text())
    readme = (site / 'standard_docs' / 'original' / 'README.html').read_text()
    assert 'src="../../_images/confusion-ujiindoorloc.png"' in readme
    assert 'href="../../start-here.html"' in readme
    assert _loads_the_style(site, 'design.html')
    assert _loads_the_style(site, 'standard_docs/original/README.html')


def _loads_the_style(site, page):
    """Return True if a built page links the style and the site has it."""
    depth = '../' * page.count('/')
    return f'href="{depth}_static/{STYLE.name}' in (site / page).read_text() \
        and (site / '_static' / STYLE.name).read_text() == STYLE.read_text()


def test_conf_finds_the_checkout_when_rosdoc2_runs_it(tmp_path):
    # rosdoc2's conf.py runs ours with exec: __file__ is the wrapper's
    wrapper = tmp_path / 'wrapped_sphinx_directory' / 'conf.py'
    wrapper.parent.mkdir()
    wrapper.write_text(f'exec(open("{DOC / "conf.py"}").read())\n')
    out = run([sys.executable, '-c', 'import runpy, sys; '
               f'runpy.run_path("{wrapper}"); print(sys.path[0])'])
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(REPO)


def test_api_pages_cover_every_module():
    pages = ''.join((DOC / 'api' / f'{p}.md').read_text()
                    for p in ('core', 'data', 'training'))
    documented = set(re.findall(r'automodule:: (\S+)', pages))
    package = REPO / 'wifi_place_recognition'
    modules = {'.'.join(('wifi_place_recognition',) + m.relative_to(
        package).with_suffix('').parts).removesuffix('.__init__')
               for p in ('core', 'data', 'training')
               for m in (package / p).rglob('*.py')
               if m.parent != package / p or m.stem != '__init__'}
    assert sorted(modules - documented) == [], 'add to doc/api/'
    assert sorted(documented - modules) == [], 'gone: remove from doc/api/'


def _index():
    """Return {file: (cited by, command)} of benchmarks/results/README.md."""
    rows = {}
    for line in (RESULTS / 'README.md').read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) == 3 and re.fullmatch(r'`[\w.-]+`', cells[0]):
            rows[cells[0].strip('`')] = tuple(cells[1:])
    return rows


def test_results_index_lists_every_file_and_who_cites_it():
    index = _index()
    files = {p.name for p in RESULTS.iterdir() if p.name != 'README.md'}
    assert sorted(files - set(index)) == [], 'add to results/README.md'
    assert sorted(set(index) - files) == [], 'gone: remove from the index'
    for name, (cited_by, command) in index.items():
        citing = re.findall(r'`([\w./-]+\.(?:md|py))`', cited_by)
        assert citing, name
        for page in citing:
            assert name in (REPO / page).read_text(), (name, page)
        assert command, name


def _png_text(path):
    """Return {key: text} of a PNG file's tEXt chunks."""
    data, found = path.read_bytes()[8:], {}
    while data:
        size, kind = int.from_bytes(data[:4], 'big'), data[4:8]
        if kind == b'tEXt':
            key, _, value = data[8:8 + size].partition(b'\0')
            found[key.decode()] = value.decode('latin-1')
        data = data[12 + size:]
    return found


def test_pictures_are_drawn_from_the_committed_json(tmp_path):
    out = run([sys.executable, str(REPO / 'benchmarks' / 'figures.py'),
               '--out', str(tmp_path)], cwd=REPO)
    assert out.returncode == 0, out.stderr
    drawn = sorted(p.name for p in tmp_path.glob('*.png'))
    assert drawn == sorted(p.name for p in (DOC / 'images').glob('*.png'))
    for name in drawn:
        # Same data: the JSON each picture records is the JSON of today.
        committed = _png_text(DOC / 'images' / name).get('Source')
        assert committed == _png_text(tmp_path / name)['Source'], \
            f'doc/images/{name} is stale: run benchmarks/figures.py'

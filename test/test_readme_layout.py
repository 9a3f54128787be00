"""The README's layout section lists the tracked files, and only those."""

import shutil

from conftest import REPO, run
import pytest


def layout():
    """Return the paths the README's "Layout" block lists (files only)."""
    text = (REPO / 'README.md').read_text()
    section = text.split('\n## Layout\n', 1)[1].split('\n## ', 1)[0]
    block = section.split('```\n', 1)[1].split('```', 1)[0]
    listed, folders = set(), []
    for line in block.splitlines():
        depth = (len(line) - len(line.lstrip(' '))) // 2
        name = line.split()[0]
        folders[depth:] = [name]
        if not name.endswith('/'):
            listed.add(''.join(folders))
    return listed


def test_readme_layout_matches_the_tracked_files():
    if shutil.which('git') is None or not (REPO / '.git').exists():
        pytest.skip('not a git checkout')
    out = run(['git', 'ls-files'], cwd=REPO)
    assert out.returncode == 0, out.stderr
    tracked = set(out.stdout.split())
    listed = layout()
    assert not sorted(tracked - listed), 'add to README "Layout"'
    assert not sorted(listed - tracked), 'gone: remove from README "Layout"'

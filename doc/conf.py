"""
Sphinx configuration: the layout rosdoc2 builds (doc/, MyST pages).

``sphinx-build doc …`` runs this file from ``doc/``. ``rosdoc2 build``
copies ``doc/`` into a wrapping project whose own ``conf.py`` runs this
file with ``exec`` (``__file__`` is then the wrapper's), adds a second
copy of the pages under ``user_docs/`` and the README under
``standard_docs/original/``: the hooks below find the checkout from the
wrapper, leave the copy out and give the README back its picture and its
links to the pages.
"""

import os
import re
import sys


def _checkout():
    """Return the repository: above this file, or above the one run."""
    here = os.path.dirname(os.path.abspath(__file__))
    with open(__file__) as f:    # rosdoc2: exec(open("<doc>/conf.py")...)
        wrapped = re.search(r'^exec\(open\("(.+?)"\)', f.read(), re.M)
    if wrapped:
        here = os.path.dirname(wrapped.group(1))
    return os.path.dirname(here)


# The package from this checkout, whether or not it is installed.
sys.path.insert(0, _checkout())

project = 'wifi_place_recognition'
author = 'wifi_place_recognition developers'
copyright = '2026, ' + author

extensions = ['myst_parser', 'sphinx.ext.autodoc', 'sphinx.ext.napoleon']
source_suffix = {'.md': 'markdown'}
exclude_patterns = ['_build', 'user_docs']    # rosdoc2's copy of the pages
myst_heading_anchors = 3
autodoc_default_options = {'members': True, 'member-order': 'bysource'}
autodoc_typehints = 'none'
napoleon_google_docstring = False
html_theme = 'alabaster'
#: Table cells that wrap in either theme (rosdoc2 overrides the theme);
#: absolute, since rosdoc2 runs this file from its own folder.
html_static_path = [os.path.join(_checkout(), 'doc', '_static')]
html_css_files = ['readable.css']

#: rosdoc2's copy of README.md, two folders below the pages.
README = 'standard_docs/original/README'


def _readme_in_the_pages(app, docname, source):
    """Point rosdoc2's README copy at the pages and pictures beside it."""
    if docname != README:
        return
    text = re.sub(r'\]\(doc/', '](../../', source[0])
    # files outside doc/ are not in the site: name them
    text = re.sub(r'\[([^\]]+)\]\(((?:benchmarks|scripts)/[^)]+)\)',
                  r'\1 (`\2` in the repository)', text)
    source[0] = '---\norphan: true\n---\n' + text


def setup(app):
    """Connect the README hook."""
    app.connect('source-read', _readme_in_the_pages)

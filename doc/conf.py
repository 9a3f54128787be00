"""Sphinx configuration: the layout rosdoc2 builds (doc/, MyST pages)."""

import os
import sys

# The package from this checkout, whether or not it is installed.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                '..'))

project = 'wifi_place_recognition'
author = 'wifi_place_recognition developers'
copyright = '2026, ' + author

extensions = ['myst_parser', 'sphinx.ext.autodoc', 'sphinx.ext.napoleon']
source_suffix = {'.md': 'markdown'}
exclude_patterns = ['_build']
myst_heading_anchors = 3
autodoc_default_options = {'members': True, 'member-order': 'bysource'}
autodoc_typehints = 'none'
napoleon_google_docstring = False
html_theme = 'alabaster'

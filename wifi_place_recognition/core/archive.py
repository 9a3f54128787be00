"""Reading zip archives (model files, the UCI zip): what a bad one raises."""

import zipfile
import zlib

#: What reading a damaged or unsupported zip archive raises: not a zip,
#: truncated, a damaged deflate stream, a zip version no reader supports.
ZIP_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, zlib.error,
              NotImplementedError)

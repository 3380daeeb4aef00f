"""MkDocs hook: MathJax 3 (``tex-svg-full.js``) into the site from the docs extra's ``django-static-mathjax``.

The math of the pages (pymdownx.arithmatex) is typeset in the browser by MathJax, served from the site itself so
that it renders offline and from file://. The SVG output needs no web fonts (a browser refuses fonts on file://
pages); ``-full`` holds every TeX extension, so MathJax loads nothing more at run time.
"""

from pathlib import Path

from mkdocs.structure.files import File

SCRIPT = "javascripts/mathjax/tex-svg-full.js"


def mathjax_dir() -> Path:
    """The folder of MathJax's es5 bundles (``es5/``) in the installed package."""
    import mathjax  # django-static-mathjax

    return Path(mathjax.__file__).parent / "static" / "mathjax" / "es5"


def on_files(files, config):
    files.append(File.generated(config, SCRIPT, abs_src_path=str(mathjax_dir() / "tex-svg-full.js")))
    return files

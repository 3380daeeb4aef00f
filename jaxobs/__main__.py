"""``python -m jaxobs``: the ``jaxobs`` command line (``jaxobs_tuning.cli.main``, every command).

An entry point, not part of the library: ``import jaxobs`` never runs this
file, so the library still never imports ``tuning/`` (data flows one
way: docs/architecture.md).  Only running the package as a program reaches the top layer, as the
``jaxobs`` console script (``jaxobs_tuning.cli_entry:main``) does.
"""

import sys

# tuning/ is installed as jaxobs_tuning by setuptools' editable finder, which pyright cannot follow
from jaxobs_tuning.cli_entry import main  # pyright: ignore[reportMissingImports]

sys.exit(main())

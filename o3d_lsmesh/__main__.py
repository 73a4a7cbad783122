"""``python -m o3d_lsmesh``: the ``o3d-lsmesh`` command line."""

import sys

from .app.cli import main

sys.exit(main())

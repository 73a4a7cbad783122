"""``python -m o3d_lsmesh.cli`` (what ``make demo`` runs)."""

import sys

from ..app.cli import main

sys.exit(main())

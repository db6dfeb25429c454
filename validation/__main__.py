"""``python -m validation [--quick] [--out DIR]``: the same as ``harvester validate``."""

from __future__ import annotations

import sys

from .harness.cli import main

sys.exit(main())

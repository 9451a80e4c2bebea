"""``python -m pscc``: the command-line interface (see :mod:`pscc.cli`)."""

from __future__ import annotations

import sys

from pscc.cli import main

sys.exit(main())

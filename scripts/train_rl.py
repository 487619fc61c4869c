#!/usr/bin/env python
"""Rl training: ``dgpt-train-rl`` run from a source tree. Options: ``--help``; the code is
:mod:`agents.rl.cli`."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.rl.cli import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())

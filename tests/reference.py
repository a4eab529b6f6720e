"""Where the tests find the project's shared reference material (never copied into the repo).

CI lays `shared/` beside the checkout; `FMSCELL_SHARED` points elsewhere (a worktree, a
packaging build). Tests that need a file from it skip with this message when it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("FMSCELL_SHARED", ROOT.parent / "shared"))
REFERENCE = SHARED / "reference"
GCODE_CORPUS = REFERENCE / "corpus" / "gcode"
PLCOPEN_CORPUS = REFERENCE / "corpus" / "plcopen"
MTCONNECT_SCHEMA = REFERENCE / "mtconnect-schema"
OPCUA_NODESETS = REFERENCE / "opcua-nodesets"
SEEDS = REFERENCE / "seeds"

MISSING = f"shared reference material not found at {SHARED} (set FMSCELL_SHARED)"

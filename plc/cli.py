"""`fmscell plc ...`: the soft-PLC's command line."""

from __future__ import annotations

import typer

plc_app = typer.Typer(help="Soft-PLC: check and run ladder programs.", no_args_is_help=True)

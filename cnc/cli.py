"""`fmscell nc ...`: the NC kernel's command line."""

from __future__ import annotations

import typer

nc_app = typer.Typer(
    help="NC kernel: check, plan and simulate part programs.", no_args_is_help=True
)

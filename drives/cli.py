"""`fmscell drives ...`: the virtual CANopen drives' command line."""

from __future__ import annotations

import typer

drives_app = typer.Typer(help="Virtual CiA 402 drives on CANopen.", no_args_is_help=True)

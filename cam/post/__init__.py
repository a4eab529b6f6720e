"""Post-processors, one per machine kind, chosen from the machine's configuration.

`POSTS` maps a machine's `kind` (the `kind:` key of its YAML) to its post; a new kind
needs only a new entry (`register_post`), never a per-machine-name branch.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from cam.cl import ClRecord
from cam.errors import CamError
from cam.post.base import FanucPost, NcBlock, PostOptions, PostSummary
from cam.post.lathe import LathePost
from cam.post.mill5 import Mill5Post
from cnc.errors import NcError

__all__ = [
    "Machine",
    "NcBlock",
    "POSTS",
    "PostOptions",
    "PostSummary",
    "load_machine",
    "post_for",
    "register_post",
]

POSTS: dict[str, type[FanucPost]] = {"mill": FanucPost, "lathe": LathePost, "mill5": Mill5Post}
CAM_KINDS = {"mill5"}  # kinds whose machine description lives in cam/ (cam.machine5)


def register_post(kind: str, cls: type[FanucPost]) -> None:
    POSTS[kind] = cls


@dataclass(frozen=True, slots=True)
class Machine:
    """A machine as a post sees it: its name, kind and configuration object."""

    name: str
    kind: str
    config: Any


def load_machine(spec: str | Path) -> Machine:
    """`mill3`, `lathe2` (the NC kernel's shipped machines), `mill5` (cam/machines/mill5.yaml)
    or a machine YAML file (its `kind` picks the loader and the post)."""
    # deferred: the machines' configurations (pydantic models) are built only when a
    # machine is loaded, not at `fmscell --help` (start-up cost)
    from cam.machine5 import MILL5_FILE, load_mill5
    from cnc.config import BUILTIN_MACHINES, builtin_machine, load_machine_config

    text = str(spec)
    if text in BUILTIN_MACHINES:
        cfg = builtin_machine(text)
        return Machine(text, cfg.kind, cfg)
    if text == "mill5":
        return Machine("mill5", "mill5", load_mill5(MILL5_FILE))
    path = Path(text)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as e:
        raise CamError(f"cannot read the machine file: {e}", 0, 0, text) from None
    if not isinstance(data, dict):
        raise CamError("a machine file is a mapping with a `kind`", 0, 0, text)
    kind = data.get("kind")
    if kind in CAM_KINDS:
        return Machine(path.stem, kind, load_mill5(path))
    try:
        cfg = load_machine_config(path)
    except NcError as e:
        raise CamError(str(e), 0, 0, text) from None
    return Machine(path.stem, cfg.kind, cfg)


def post_for(machine: Machine, options: PostOptions | None = None, file: str = "<cl>") -> FanucPost:
    """The post of the machine's kind."""
    try:
        cls = POSTS[machine.kind]
    except KeyError:
        known = ", ".join(sorted(POSTS))
        raise CamError(
            f"no post-processor for machine kind {machine.kind!r} (known: {known})",
            0,
            0,
            machine.name,
        ) from None
    return cls(machine, options, file)


def post(
    records: Iterable[ClRecord],
    machine: Machine,
    options: PostOptions | None = None,
    file: str = "<cl>",
) -> tuple[FanucPost, Iterator[NcBlock]]:
    """The post and its block stream (the summary fills as the stream is consumed)."""
    p = post_for(machine, options, file)
    return p, p.run(records)

"""Programmable transforms: G15/G16 polar, G50.1/G51.1 mirror, G50/G51 scaling, G68/G69.

The transform itself is cnc.interp.transform.Transform; these handlers set it. Their axis
words are centres or mirror lines, not a motion target.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.interp.gnum import G16, G50, G50_1, G69

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

_AXIS_OF = {"X": 0, "Y": 1, "Z": 2}
_AXIS_NAME = "XYZ"


def polar(ip: Context, run: BlockRun) -> None:
    ip._polar = run.g["polar"] == G16


def mirror(ip: Context, run: BlockRun) -> None:
    blk = run.blk
    xf = ip._xf
    named = [letter for letter in "XYZ" if letter in blk.words]
    if run.g["mirror"] == G50_1:
        for letter in named or "XYZ":
            xf.mirror[_AXIS_OF[letter]] = False
    else:
        if not named:
            raise ip._err("G51.1 needs the mirror axis position (X/Y/Z)", blk, "G")
        for letter in named:
            i = _AXIS_OF[letter]
            xf.mirror[i] = True
            xf.mirror_c[i] = ip._dim(blk, letter)
    ip._xf_changed()


def scaling(ip: Context, run: BlockRun) -> None:
    blk = run.blk
    xf = ip._xf
    if run.g["scaling"] == G50:
        xf.scale = None
        ip._xf_changed()
        return
    c = list(ip._pos)
    for letter in "XYZ":
        if letter in blk.words:
            c[_AXIS_OF[letter]] = ip._dim(blk, letter)
    words = blk.words
    if "P" in words:
        f = ip._plain(blk, "P")
        factors = [f, f, f]
    else:
        factors = [1.0, 1.0, 1.0]
        for i, letter in enumerate("IJK"):
            if letter in words:
                factors[i] = ip._plain(blk, letter)
    if any(f == 0.0 for f in factors):
        raise ip._err("scaling factor 0", blk, "P" if "P" in words else "I")
    xf.scale = factors
    xf.scale_c = c
    ip._xf_changed()


def rotation(ip: Context, run: BlockRun) -> None:
    blk = run.blk
    xf = ip._xf
    if run.g["rotation"] == G69:
        xf.rot = False
        xf.cos, xf.sin = 1.0, 0.0
        ip._xf_changed()
        return
    u, v = ip._pu, ip._pv
    names = _AXIS_NAME
    cu = ip._dim(blk, names[u]) if names[u] in blk.words else ip._pos[u]
    cv = ip._dim(blk, names[v]) if names[v] in blk.words else ip._pos[v]
    ang = ip._plain(blk, "R") if "R" in blk.words else 0.0
    was = xf.rot
    xf.rot = False
    p = [0.0, 0.0, 0.0]
    p[u], p[v] = cu, cv
    c = xf.apply(p)  # the centre is given in the mirrored/scaled system
    xf.rot = was
    xf.set_rotation((u, v), (c[u], c[v]), ang)
    ip._xf_changed()

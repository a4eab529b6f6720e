"""The 5-axis post for kind `mill5`: the B45/C table-table machine of seed 002.

Per CL point (x, y, z, i, j, k) in the workpiece frame:
* inverse kinematics (002 eqs. 10-14, `cnc.kinematics.TableTableBC45`), one branch for the
  whole program (B >= 0 by default); k < 0 is unreachable (refused with the CL line), k = 1
  is singular (C undefined: the previous C is kept, the record's line is reported);
* C unwrapped to the turn nearest the previous C (shortest path), within the C limits
  when the table is not endless; every axis checked against its limits;
* linearisation: the NC interpolates the five joints linearly, so between two CL points
  the tool tip follows a curve. Each CL segment is bisected recursively until, at the
  midpoint of every sub-segment, the tool tip (forward kinematics of the joint midpoint)
  is within T of the CL midpoint; the inserted points are exact CL-space midpoints with
  the normalised mean tool axis (002 §3: depth-first bisection, t = 0.5).
Rapid moves are positioning and are not linearised; nor is the first move of a program
(the machine's position before it is not known).
"""

from __future__ import annotations

import math
from collections.abc import Iterator

from cam.cl import ClRecord
from cam.post.base import INCH, SINGULAR_LIST_MAX, FanucPost, NcBlock, fmt

_sqrt, _acos, _atan2, _cos, _sin = math.sqrt, math.acos, math.atan2, math.cos, math.sin
_DEG, _RAD = 180.0 / math.pi, math.pi / 180.0
SINGULAR_K = 1e-12  # as cnc.kinematics: k this close to 1 is the singular orientation
SINGULAR_STEP = 1e-4  # how far along a segment C's limit at its singular end is taken
C_JUMP_WARN = 90.0  # degrees of C in one block: flagged (002 req 13)
_H = math.sqrt(0.5)


class Mill5Post(FanucPost):
    kind = "mill5"
    name = "fanuc-mill5"
    axes = ("X", "Y", "Z", "B", "C")

    def __init__(self, machine, options=None, file: str = "<cl>") -> None:
        super().__init__(machine, options, file)
        cfg = machine.config
        self.cfg = cfg
        self.sigma = 1.0 if cfg.kinematics.branch == "positive" else -1.0
        t = self.opt.tolerance_mm if self.opt.tolerance_mm is not None else cfg.post.tolerance_mm
        if not t > 0:
            raise ValueError("the tolerance T must be > 0")
        self.tol_mm = t
        self.ready = False
        self.joints: tuple[float, float, float, float, float] | None = None  # of self.anchor
        self.prev_c: float | None = None
        self.last_singular = -1  # CL line of the last singular record
        self.sent: tuple = ()  # the CL pose and joints of the last block sent (inverse time)
        self.block_minutes: float | None = None
        self.singular_ik = False  # the last inverse kinematics met the singular orientation
        self.allow_unwind = False  # a rapid may turn C the long way round within the limits
        self.joints_singular = False  # self.joints are at the singular orientation

    def merge_tol(self) -> float:
        return self.tol_mm / INCH if self.units == "INCHES" else self.tol_mm

    def check_axis(self, vec, rec) -> None:
        return None  # any tool axis; reachability is the inverse kinematics' business

    # --- constants in program units (fixed at the first motion: UNITS cannot change after) -----

    def _setup(self) -> None:
        if self.ready:
            return
        self.ready = True
        k = 1.0 / INCH if self.units == "INCHES" else 1.0
        kin = self.cfg.kinematics
        self.d = kin.d_mm * k
        self.tl = kin.tool_length_mm * k
        self.zo = kin.z_offset_mm * k
        self.T = self.tol_mm * k
        ax = self.cfg.axes
        self.lim = {
            "X": (ax.X.min * k, ax.X.max * k),
            "Y": (ax.Y.min * k, ax.Y.max * k),
            "Z": (ax.Z.min * k, ax.Z.max * k),
        }
        self.b_lim = (ax.B.min, ax.B.max)
        self.c_lim = None if ax.C.continuous else (ax.C.min, ax.C.max)
        lin = self.cfg.post.linear_decimals + (1 if self.units == "INCHES" else 0)
        rot = self.cfg.post.rotary_decimals
        self.dec = {"X": lin, "Y": lin, "Z": lin, "B": rot, "C": rot}
        self.fmt_linear, self.fmt_rotary = f"%.{lin}f", f"%.{rot}f"
        self.inverse_time = self.cfg.post.feed == "inverse_time"
        self.last5: list[str | None] = [None] * 5  # the axis words the NC has
        e = 1e-9
        self.bounds = (
            self.lim["X"][0] - e, self.lim["X"][1] + e, self.lim["Y"][0] - e, self.lim["Y"][1] + e,
            self.lim["Z"][0] - e, self.lim["Z"][1] + e, self.b_lim[0] - e, self.b_lim[1] + e,
        )  # fmt: skip
        self.max_depth = self.opt.max_depth if self.opt.max_depth else self.cfg.post.max_depth

    # --- kinematics ----------------------------------------------------------------------------

    def ik(
        self, pose: tuple[float, ...], prev_c: float | None, rec: ClRecord, report: bool = True
    ) -> tuple[float, float, float, float, float]:
        """Joints (X, Y, Z, B, C) of a CL pose; the closed forms of cnc.kinematics.bc45_inverse
        with the branch sign, C unwrapped next to prev_c and the limits applied."""
        x0, y0, z0, i, j, k = pose
        n2 = i * i + j * j + k * k
        if not -1e-15 <= n2 - 1.0 <= 1e-15:
            n = _sqrt(n2)
            if not abs(n - 1.0) <= 1e-3:
                raise self.err(
                    f"tool axis ({i:.6g}, {j:.6g}, {k:.6g}) is not a unit vector (|v| = {n:.6g})",
                    rec,
                )
            i, j, k = i / n, j / n, k / n
        if k < -1e-12:
            raise self.err(
                f"orientation unreachable: tool axis ({i:.6g}, {j:.6g}, {k:.6g}) has k < 0;"
                " the B45/C table tilts the part by at most 90 degrees",
                rec,
            )
        k = min(max(k, 0.0), 1.0)
        self.singular_ik = 1.0 - k <= SINGULAR_K
        if self.singular_ik:
            b, s, m, kk = 0.0, 0.0, 1.0, 1.0
            c = prev_c if prev_c is not None else 0.0
            sm = self.summary
            if report and rec.line != self.last_singular:
                self.last_singular = rec.line
                sm.singular_count += 1
                if len(sm.singular) < SINGULAR_LIST_MAX:
                    sm.singular.append(rec.line)
                if sm.singular_count == 1:
                    self.warn(
                        "singular orientation: the tool axis is parallel to C (B = 0), C kept at"
                        f" {c:.4f} (every singular record is listed in the summary)",
                        rec,
                    )
        else:
            m = 2.0 * k - 1.0
            sigma = self.sigma
            b = sigma * _acos(m) * _DEG
            kk = (1.0 + m) * 0.5
            q = 2.0 * (kk - kk * kk)
            s = sigma * _sqrt(q) if q > 0.0 else 0.0
            c = _atan2((kk - 1.0) * i + s * j, (kk - 1.0) * j - s * i) * _DEG
            if prev_c is None or not -180.0 < c - prev_c <= 180.0 or self.c_lim is not None:
                c = self._unwrap(c, prev_c, rec)
        cr = c * _RAD
        cc, sc = _cos(cr), _sin(cr)
        d = self.d
        x = (m * x0 + s * y0) * cc + (s * x0 - m * y0) * sc + s * (d + z0)
        y = (kk * y0 - s * x0) * cc + (kk * x0 + s * y0) * sc + (kk - 1.0) * (d + z0)
        z = (
            ((kk - 1.0) * y0 - s * x0) * cc
            + ((kk - 1.0) * x0 + s * y0) * sc
            + (kk - 1.0) * d
            + kk * z0
        )
        z = z - self.zo + self.tl
        return (x, y, z, b, c)

    def _unwrap(self, c: float, prev: float | None, rec: ClRecord) -> float:
        """The turn of C nearest the previous C (the shortest path). With C limits a cutting
        move must still take the shortest path (the table cannot unwind while the tool cuts:
        the tool axis would sweep round); a rapid may take the other way round."""
        ref = prev if prev is not None else 0.0
        c = c + 360.0 * round((ref - c) / 360.0)
        if self.c_lim is None:
            return c
        lo, hi = self.c_lim
        if lo - 1e-9 <= c <= hi + 1e-9:
            return c
        if self.allow_unwind or prev is None:
            cands = [c + 360.0 * t for t in range(-3, 4) if lo - 1e-9 <= c + 360.0 * t <= hi + 1e-9]
            if cands:
                return min(cands, key=lambda v: abs(v - ref))
        raise self.err(
            f"C {c:.4f} beyond the C limits ({lo:g} ... {hi:g}): the table would have to"
            " unwind during a cutting move (reposition with a RAPID first)",
            rec,
        )

    def fk_tip(
        self, x: float, y: float, z: float, b: float, c: float
    ) -> tuple[float, float, float]:
        """The tool tip in the workpiece frame (cnc.kinematics.bc45_forward, point only):
        P0 = Rz(-C) T(0,0,-d) Rx(45) Rz(B) Rx(-45) T(0,0,d) Pw."""
        d = self.d
        pz = z + self.zo - self.tl + d
        y1 = _H * (y + pz)
        z1 = _H * (pz - y)
        br, cr = b * _RAD, c * _RAD
        cb, sb = _cos(br), _sin(br)
        x2 = cb * x - sb * y1
        y2 = sb * x + cb * y1
        y3 = _H * (y2 - z1)
        z3 = _H * (y2 + z1)
        cc, sc = _cos(cr), _sin(cr)
        return (cc * x2 + sc * y3, -sc * x2 + cc * y3, z3 - d)

    # --- motion --------------------------------------------------------------------------------

    def emit_linear(self, pose: tuple[float, ...], rec: ClRecord, rapid: bool) -> Iterator[NcBlock]:
        self._setup()
        out: list[NcBlock] = []
        prev_c = self.joints[4] if self.joints is not None else self.prev_c
        self.allow_unwind = rapid
        joints = self.ik(pose, prev_c, rec)
        self.allow_unwind = False
        singular = self.singular_ik
        if rapid or self.joints is None or self.anchor is None:
            self.emit_joints(joints, rec, rapid, pose, out)
        else:
            if self.joints_singular and not singular and abs(joints[4] - self.joints[4]) > 1e-9:
                # Leaving the singular orientation: C was free there (kept from before) and
                # now has a value. Turn C at the singular point first, to C's limit
                # approaching B = 0 along this segment (the kinematics is smooth there but
                # for C), the tool tip held on the CL point within T by the same bisection
                # with both ends at one pose.
                a, v = self.anchor, pose
                near = [a[3 + q] + SINGULAR_STEP * (v[3 + q] - a[3 + q]) for q in range(3)]
                nn = math.sqrt(sum(x * x for x in near))
                c_near = self.ik((*a[:3], *(x / nn for x in near)), joints[4], rec, report=False)[4]
                turned = self.ik(self.anchor, c_near, rec, report=False)
                self.linearise(self.anchor, self.joints, self.anchor, turned, rec, 0, out)
                self.joints = turned
            self.linearise(self.anchor, self.joints, pose, joints, rec, 0, out)
        self.joints = joints
        self.joints_singular = singular
        return iter(out)

    def linearise(self, pa, ja, pb, jb, rec: ClRecord, depth: int, out: list[NcBlock]) -> None:
        """Depth-first bisection of the CL segment pa-pb (joints ja-jb) until the tool tip at
        every sub-segment's joint midpoint is within T of the CL midpoint; blocks to `out`."""
        tip = self.fk_tip(
            (ja[0] + jb[0]) * 0.5, (ja[1] + jb[1]) * 0.5, (ja[2] + jb[2]) * 0.5,
            (ja[3] + jb[3]) * 0.5, (ja[4] + jb[4]) * 0.5,
        )  # fmt: skip
        ex = tip[0] - (pa[0] + pb[0]) * 0.5
        ey = tip[1] - (pa[1] + pb[1]) * 0.5
        ez = tip[2] - (pa[2] + pb[2]) * 0.5
        dev = math.sqrt(ex * ex + ey * ey + ez * ez)
        if dev <= self.T:
            if dev > self.summary.peak_deviation:
                self.summary.peak_deviation = dev
            self.emit_joints(jb, rec, False, pb, out)
            return
        if depth >= self.max_depth:
            raise self.err(
                f"linearisation did not reach T = {self.tol_mm:g} mm after {depth} bisections"
                f" (deviation {dev:.6g}): the segment passes too close to the singular"
                " orientation",
                rec,
            )
        i, j, k = (pa[3] + pb[3]) * 0.5, (pa[4] + pb[4]) * 0.5, (pa[5] + pb[5]) * 0.5
        n = math.sqrt(i * i + j * j + k * k)
        if n < 1e-9:
            raise self.err("the tool axis turns by 180 degrees in one CL segment", rec)
        pm = (
            (pa[0] + pb[0]) * 0.5, (pa[1] + pb[1]) * 0.5, (pa[2] + pb[2]) * 0.5,
            i / n, j / n, k / n,
        )  # fmt: skip
        jm = self.ik(pm, (ja[4] + jb[4]) * 0.5, rec, report=False)
        self.summary.points_inserted += 1
        self.linearise(pa, ja, pm, jm, rec, depth + 1, out)
        self.linearise(pm, jm, pb, jb, rec, depth + 1, out)

    def emit_joints(self, j, rec: ClRecord, rapid: bool, pose, out: list[NcBlock]) -> None:
        x, y, z, b, c = j
        if self.opt.trace is not None:
            self.opt.trace.append((tuple(pose), j))
        lx, hx, ly, hy, lz, hz, lb, hb = self.bounds
        if not (lx <= x <= hx and ly <= y <= hy and lz <= z <= hz and lb <= b <= hb):
            self._limit_error(j, rec)
        pc = self.prev_c
        if pc is not None and not -C_JUMP_WARN <= c - pc <= C_JUMP_WARN:
            self.warn(
                f"C turns by {c - pc:.1f} degrees in one block (near the singular orientation)",
                rec,
            )
        self.prev_c = c
        # the axis words, modal (Fanuc number style as fmt(), inlined: this runs per block)
        last = self.last5
        fl, fr = self.fmt_linear, self.fmt_rotary
        words = []
        for q, name, v, f in (
            (0, "X", x, fl),
            (1, "Y", y, fl),
            (2, "Z", z, fl),
            (3, "B", b, fr),
            (4, "C", c, fr),
        ):
            w = (f % v).rstrip("0")
            if w == "-0.":
                w = "0."
            if last[q] != w:
                words.append(name + w)
                last[q] = w
        if not words:
            return
        if self.inverse_time and not rapid:
            self.block_minutes = self._minutes(pose, j, rec)
        self.sent = (pose, j)
        if not self.header_done:
            out.extend(self.header(rec))
        text = self.motion_text(" ".join(words), rec, rapid)
        if self.ended:
            raise self.err("output after the end of the program (FINI or END)", rec)
        self.summary.blocks_out += 1
        self.last_text = text
        out.append(NcBlock(text, rec.line))

    def _minutes(self, pose, j, rec: ClRecord) -> float | None:
        """Inverse time: how long the block takes, from the tool tip's path length in the
        workpiece frame at the programmed feed; a block that only turns the table takes
        the configured rotary rate."""
        if self.feed is None:
            raise self.err("a cutting move without a feed rate (FEDRAT before it)", rec)
        if self.feed_per_rev:
            raise self.err("inverse-time feed (G93) cannot take a feed per revolution", rec)
        if not self.sent:
            return None  # from where the machine happens to be: a feed per minute
        pa, ja = self.sent
        length = math.dist(pa[:3], pose[:3])
        turn = max(abs(j[3] - ja[3]), abs(j[4] - ja[4]))
        return max(length / self.feed, turn / self.cfg.post.rotary_feed_deg_min)

    def feed_words(self, rec: ClRecord) -> str:
        if not self.inverse_time or self.block_minutes is None:
            return super().feed_words(rec)
        words = ""
        if self.feed_mode_out != "G93":
            words = " G93"
            self.feed_mode_out = "G93"  # type: ignore[assignment]
        self.feed_out = None  # a later G94 block must give its F again
        minutes = max(self.block_minutes, 1e-9)
        return words + " F" + fmt(1.0 / minutes, 3)  # in every G93 block: it is not modal

    def _limit_error(self, j, rec: ClRecord) -> None:
        for name, v in zip("XYZ", j, strict=False):
            lo, hi = self.lim[name]
            if not lo - 1e-9 <= v <= hi + 1e-9:
                raise self.err(
                    f"{name} {v:.4f} beyond the {name} travel ({lo:g} ... {hi:g}) after posting",
                    rec,
                )
        raise self.err(
            f"B {j[3]:.4f} beyond the B limits ({self.b_lim[0]:g} ... {self.b_lim[1]:g})", rec
        )

    def arc_move(self, arc: ClRecord, pose: tuple[float, ...], rec: ClRecord) -> Iterator[NcBlock]:
        """A CL arc as chords whose sagitta is within T (each chord then linearised)."""
        if self.pos is None:
            raise self.err("an arc needs a known start (a GOTO or FROM before the CIRCLE)", arc)
        self._setup()
        c = arc.numbers
        centre, axis, r = c[0:3], c[3:6], c[6]
        ax = [float(v) for v in axis]
        an = math.sqrt(sum(v * v for v in ax))
        ax = [v / an for v in ax]
        sx = [self.pos[q] - centre[q] for q in range(3)]
        ex = [pose[q] - centre[q] for q in range(3)]
        ha = sum(sx[q] * ax[q] for q in range(3))
        hb = sum(ex[q] * ax[q] for q in range(3))
        u = [sx[q] - ha * ax[q] for q in range(3)]
        ru = math.sqrt(sum(v * v for v in u))
        w = [ex[q] - hb * ax[q] for q in range(3)]
        rw = math.sqrt(sum(v * v for v in w))
        tol = 1e-4 * (1 + abs(r)) + self.T
        if abs(ru - r) > tol or abs(rw - r) > tol:
            raise self.err(f"arc end points are not on the circle of radius {r:.6g}", rec)
        u = [v / ru for v in u]
        v_ = [ax[1] * u[2] - ax[2] * u[1], ax[2] * u[0] - ax[0] * u[2], ax[0] * u[1] - ax[1] * u[0]]
        sweep = math.atan2(sum(w[q] * v_[q] for q in range(3)), sum(w[q] * u[q] for q in range(3)))
        if sweep <= 1e-12:
            sweep += 2 * math.pi
        step = 2 * math.acos(max(-1.0, 1 - self.T / r)) if r > self.T else math.pi / 2
        n = max(1, math.ceil(sweep / step))
        self.summary.arc_points += n - 1
        start = self.pos
        for q in range(1, n + 1):
            t = q / n
            a = sweep * t
            ca, sa = math.cos(a), math.sin(a)
            h = ha + (hb - ha) * t
            p = [centre[e] + r * (ca * u[e] + sa * v_[e]) + h * ax[e] for e in range(3)]
            if q == n:
                p = list(pose[:3])
            orient = pose[3:] if len(pose) >= 6 else start[3:]
            sub = (p[0], p[1], p[2], *orient)
            yield from self.emit_linear(sub, rec, False)
            self.anchor = sub

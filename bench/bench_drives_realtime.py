"""Realtime: 6 CSP axes at a 1 ms SYNC on the wall clock, late cycles and lateness.

6 axes at 1 ms do not fit one 1 Mbit/s line, so two CAN lines of 3 axes. Two ways to run
in real time (`--mode`):

* paced (default): the deterministic lockstep core (hubs, drives, axis group) stepped from
  one thread, each IPO cycle started at its absolute wall-clock deadline; a cycle is late
  when its work (frames, drive plants) ends after the next SYNC is due.
* threaded: realtime hubs deliver and tick their drives from their own threads
  (`VirtualDrive.start()`), the axis group waits for the TPDOs; a cycle is late when not
  every TPDO arrived before the next SYNC was due.

Target: < 0.1 % late cycles over 60 s (`--seconds` to shorten). Judged on
`late_or_missed_pct`: late cycles plus the slots skipped because the thread came back more
than a whole period late (no SYNC went out in them), over all slots.

The peer: before each paced run the same `Pacer`, with the same scheduling, paces a cycle
that does no work for as long (`peer_no_work_pacer`; `--peer-seconds 0` skips it). A late
slot there is the box's (scheduler, other processes, the VM), not the drives' code: read the
two side by side. `--c-peer` adds the same no-work pacer in C (`bench/rt_peer.c`, built with
gcc at run time), which rules the interpreter out too; `--peer-busy-us N` a peer that spins
N us per cycle (`peer_busy_pacer`): as long on a CPU as the drives, none of their code.

Each run also reports where its pacing thread's time went (`/proc/thread-self/schedstat`):
`runqueue_wait_ms` is time it was ready to run but another task had the CPU, with the
involuntary context switches and the box's steal time (the hypervisor's) over the run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drives import VirtualDrive  # noqa: E402
from drives.bus import BusLoadWarning, CanHub  # noqa: E402
from drives.master import AxisConfig, AxisGroup  # noqa: E402
from drives.realtime import RT_CPU_ENV, RT_PRIORITY_ENV, Pacer, RealtimeProcess  # noqa: E402

TARGET_LATE_PCT = 0.1
PERIOD_S = 0.001
NAMES = ["X", "Y", "Z", "A", "B", "C"]
C_PEER = Path(__file__).with_name("rt_peer.c")


class ThreadAccount:
    """Where the calling thread's time went between `start()` and `stop()`: on a CPU,
    waiting on a run queue, preempted; and the box's steal time meanwhile."""

    def start(self) -> ThreadAccount:
        self._t0 = self._read()
        return self

    def stop(self) -> dict:
        (run1, wait1, nivcsw1, steal1), (run0, wait0, nivcsw0, steal0) = self._read(), self._t0
        out = {"involuntary_switches": nivcsw1 - nivcsw0}
        if run0 is not None and run1 is not None:
            out["on_cpu_s"] = round((run1 - run0) / 1e9, 3)
            out["runqueue_wait_ms"] = round((wait1 - wait0) / 1e6, 1)
        if steal0 is not None and steal1 is not None:
            out["box_steal_ms"] = round((steal1 - steal0) * 1000 / os.sysconf("SC_CLK_TCK"), 1)
        return out

    @staticmethod
    def _read() -> tuple[int | None, int | None, int, int | None]:
        run = wait = steal = None
        try:  # Linux: on-CPU ns, run-queue wait ns, timeslices
            with open("/proc/thread-self/schedstat") as f:
                run, wait = (int(v) for v in f.read().split()[:2])
        except OSError:
            pass
        try:  # the 8th figure of the "cpu" line: time the hypervisor ran something else
            with open("/proc/stat") as f:
                steal = int(f.readline().split()[8])
        except (OSError, IndexError, ValueError):
            pass
        return run, wait, resource.getrusage(resource.RUSAGE_THREAD).ru_nivcsw, steal


def slot_figures(cycles: int, late: int, skipped: int) -> dict:
    """Late cycles, and late or missed slots (a skipped slot sent no SYNC) over all slots."""
    slots = cycles + skipped
    return {
        "late_or_missed_slots": late + skipped,
        "late_or_missed_pct": 100.0 * (late + skipped) / slots if slots else 0.0,
    }


def percentile(ordered: list[float], q: float) -> float:
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else 0.0


def peer_no_work(seconds: float, busy_s: float = 0.0) -> dict:
    """The drives' pacer and process settings with no work in the cycle: the box's share.

    `busy_s` > 0: the cycle spins that long instead (no allocation, no frames), as long on
    the CPU as the drives' work but none of their code.
    """
    pacer = Pacer(PERIOD_S)  # the same scheduling request as the drives run (environment)
    RealtimeProcess.acquire()
    try:
        pacer.wait()
        lateness = []
        account = ThreadAccount().start()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        late, clock = 0, time.perf_counter
        for _ in range(round(seconds / PERIOD_S)):
            lateness.append(pacer.wait())
            if busy_s:
                end = clock() + busy_s
                while clock() < end:
                    pass
            if clock() > pacer.slot + PERIOD_S:  # as the paced group counts a late cycle
                late += 1
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        where = account.stop()
    finally:
        pacer.restore_scheduling()
        RealtimeProcess.release()
    ordered = sorted(lateness)
    figures = slot_figures(len(lateness), late, pacer.skipped)
    return {
        "busy_us": round(busy_s * 1e6, 1),
        "cycles": len(lateness),
        "late_cycles": late,
        "skipped_slots": pacer.skipped,
        **figures,
        "lateness_p50_us": round(percentile(ordered, 0.50) * 1e6, 1),
        "lateness_p99_us": round(percentile(ordered, 0.99) * 1e6, 1),
        "lateness_max_us": round(ordered[-1] * 1e6 if ordered else 0.0, 1),
        # as the drives run counts them: a stall of half a period or more in the wait
        "woke_late_cycles": sum(1 for x in lateness if x > PERIOD_S / 2),
        "cpu_s": round(cpu, 3),
        "wall_s": round(wall, 3),
        **where,
        "scheduling": pacer.scheduling,
        "meets_target": figures["late_or_missed_pct"] < TARGET_LATE_PCT,
    }


def c_peer(seconds: float, rt_priority: int, cpu: int | None) -> dict:
    """The same no-work pacer in C (sleep to 250 us before the slot, then spin)."""
    gcc = shutil.which("gcc") or shutil.which("cc")
    if gcc is None:
        return {"skipped": "no C compiler on this box"}
    with tempfile.TemporaryDirectory() as tmp:
        exe = os.path.join(tmp, "rt_peer")
        subprocess.run([gcc, "-O2", "-o", exe, str(C_PEER)], check=True)
        done = subprocess.run(
            [exe, str(seconds), str(rt_priority), str(-1 if cpu is None else cpu)],
            check=True,
            capture_output=True,
            text=True,
        )
    out = json.loads(done.stdout)
    out["meets_target"] = out["late_or_missed_pct"] < TARGET_LATE_PCT
    return out


def run(mode: str, seconds: float, substep: float) -> dict:
    hub_mode = "realtime" if mode == "threaded" else "lockstep"
    hubs = [CanHub(channel=f"can{i}", mode=hub_mode) for i in (0, 1)]
    drives = [
        VirtualDrive(n, hub.endpoint(f"n{n}"), substep=substep) for hub in hubs for n in (1, 2, 3)
    ]
    if mode == "threaded":
        for d in drives:
            d.start()
    axes = [AxisConfig(name, i % 3 + 1, line=i // 3) for i, name in enumerate(NAMES)]
    group = AxisGroup(
        [h.endpoint("master") for h in hubs],
        axes,
        ipo_cycle_s=PERIOD_S,
        following_error_every=4,
        paced=mode == "paced",
    )
    try:
        group.boot()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BusLoadWarning)
            group.configure()
        group.enable()
        start = {n: group.position_mm(n) for n in NAMES}
        group.stats = type(group.stats)()  # measure the steady run only
        collections = list(RealtimeProcess.collections)
        postponed = RealtimeProcess.middle_postponed
        account = ThreadAccount().start()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        for k in range(round(seconds / PERIOD_S)):
            t = k * PERIOD_S
            group.cycle(
                {n: start[n] + 10.0 * math.sin(2 * math.pi * t + i) for i, n in enumerate(NAMES)}
            )
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        where = account.stop()
        stats = group.stats
        summary = stats.summary()
        faults = len(group.fault_log)
        gc_in_slack = [b - a for a, b in zip(collections, RealtimeProcess.collections, strict=True)]
        gc_postponed = RealtimeProcess.middle_postponed - postponed
        late_ticks = sum(h.late_ticks for h in hubs)
        scheduling = group.scheduling if mode == "paced" else "threads: SCHED_OTHER"
    finally:
        group.close()
        for hub in hubs:
            hub.close()
    figures = slot_figures(stats.cycles, stats.late_cycles, stats.skipped_slots)
    if mode == "paced":  # SYNC sent -> the cycle's work done, not a TPDO wait
        summary["cycle_work_p50_us"] = summary.pop("tpdo_latency_p50_us")
        summary["cycle_work_p99_us"] = summary.pop("tpdo_latency_p99_us")
        summary["cycle_work_max_us"] = max(stats.tpdo_latency_s, default=0.0) * 1e6
        # a cycle that starts half a period late had its stall in the wait (the OS), not in
        # the drives' work; compare with late_cycles
        summary["woke_late_cycles"] = sum(1 for x in stats.lateness_s if x > PERIOD_S / 2)
    else:
        summary["drive_ticks_late"] = late_ticks
    return {
        **summary,
        **figures,
        # CPU of this process over the run (threads included) and the box's load: a late
        # cycle on a busy shared box is mostly the scheduler's, not the work's
        "cpu_s": round(cpu, 3),
        "wall_s": round(wall, 3),
        **where,
        "load_average_1min": round(os.getloadavg()[0], 2),
        "gc_collections_in_slack": gc_in_slack,  # young, middle
        "gc_middle_postponed": gc_postponed,  # due, but longer than any slack so far
        "faults": faults,
        "scheduling": scheduling,
        "meets_target": figures["late_or_missed_pct"] < TARGET_LATE_PCT,
    }


def paced_with_peer(args) -> dict:
    """The peer (no work) then the drives, with the scheduling the environment asks for."""
    out = {}
    if args.peer_seconds:
        out["peer_no_work_pacer"] = peer_no_work(args.peer_seconds)
        if args.peer_busy_us:
            out["peer_busy_pacer"] = peer_no_work(args.peer_seconds, args.peer_busy_us * 1e-6)
    out.update(run("paced", args.seconds, args.substep))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0, help="per mode")
    parser.add_argument("--mode", choices=("paced", "threaded", "both"), default="paced")
    parser.add_argument("--substep", type=float, default=1e-3, help="plant sub-step, s")
    parser.add_argument(
        "--rt-priority",
        type=int,
        default=50,
        help="SCHED_FIFO priority of the pacing thread for the second paced run (0 = skip it)",
    )
    parser.add_argument(
        "--peer-seconds",
        type=float,
        default=None,
        help="the no-work pacer before each paced run (default: --seconds; 0 = skip)",
    )
    parser.add_argument(
        "--rt-cpu",
        type=int,
        default=None,
        help="also pin the pacing thread of the SCHED_FIFO run to this CPU (FMSCELL_DRIVES_RT_CPU)",
    )
    parser.add_argument("--c-peer", action="store_true", help="also the no-work pacer in C")
    parser.add_argument(
        "--peer-busy-us",
        type=float,
        default=0.0,
        help="also a peer that spins this long per cycle (e.g. the drives' cycle_work_p50_us)",
    )
    args = parser.parse_args()
    if args.peer_seconds is None:
        args.peer_seconds = args.seconds
    modes = ("paced", "threaded") if args.mode == "both" else (args.mode,)
    out = {
        "benchmark": "drives_realtime",
        "seconds": args.seconds,
        "configuration": "6 CSP axes, 1 ms SYNC, 2 CAN lines x 3 axes at 1 Mbit/s, "
        f"plant sub-step {args.substep * 1e6:g} us",
        "target": f"< {TARGET_LATE_PCT} % late or missed slots",
    }
    for mode in modes:
        if mode == "paced":
            if args.c_peer:
                out["paced_c_peer"] = c_peer(args.peer_seconds or args.seconds, 0, None)
            out["paced"] = paced_with_peer(args)
        else:
            out[mode] = run(mode, args.seconds, args.substep)
    if "paced" in modes and args.rt_priority:
        # the same with the pacing thread at SCHED_FIFO (opt-in in drives.realtime); the
        # pacer promotes the calling thread, this one, and puts it back when it is done
        os.environ[RT_PRIORITY_ENV] = str(args.rt_priority)
        if args.rt_cpu is not None:
            os.environ[RT_CPU_ENV] = str(args.rt_cpu)
        try:
            if args.c_peer:
                out["paced_sched_fifo_c_peer"] = c_peer(
                    args.peer_seconds or args.seconds, args.rt_priority, args.rt_cpu
                )
            out["paced_sched_fifo"] = paced_with_peer(args)
        finally:
            os.environ.pop(RT_PRIORITY_ENV, None)
            os.environ.pop(RT_CPU_ENV, None)
    print(json.dumps(out))


if __name__ == "__main__":
    main()

"""End to end: seed 004's synthetic APT program (req 15) uploaded as APT, posted at dispatch
for the mill, sent over the machine's real DNC port (verified transfer) and run on the
complete simulated mill: it ends at (4, 8, 6) in with the PLC trace of tool, spindle and
coolant (the bookkeeping on both databases is in test_posting.py)."""

from __future__ import annotations

import threading

from cnc.machine import Machine
from dnc.db import make_engine, migrate, session_factory
from dnc.dispatch import Dispatches
from dnc.library import Library
from dnc.transfer_worker import TransferWorker
from tests.cam.test_e2e_sim import check_seed15_trace, run_seed15
from tests.cam.test_post import SEED15

from .test_posting import G54_ROOM, mill_with_room


def test_seed15_apt_posted_dispatched_and_run_on_the_simulated_mill(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'host.db'}")
    migrate(engine)
    sessions = session_factory(engine)
    cfg = mill_with_room()

    def configs(name: str, kind: str):
        return {"mill1": cfg}.get(name)  # the host knows the cell's machine configuration

    lib = Library(sessions, machine_configs=configs)
    machine = Machine(cfg, "mill1")
    try:
        faces = machine.start_faces()
        machine.power_on()  # home, AUTO, in lockstep
        lib.register_machine("mill1", "mill", dnc_address=f"127.0.0.1:{faces.ports()['dnc']}")
        _, rev = lib.create_program(number=15, name="TEST1", text=SEED15, kind="apt")
        lib.release(rev.id, approver="ann", comment="seed 004 req 15")
        dispatch, _ = Dispatches(sessions, machine_configs=configs).request(
            key="seed15", revision_id=rev.id, machine="mill1"
        )
        done: dict = {}
        worker = threading.Thread(
            target=lambda: done.setdefault("state", TransferWorker(sessions).run(dispatch.id))
        )
        worker.start()
        # the machine runs while the host transfers (its faces answer between cycles)
        machine.run_until(lambda mm: not worker.is_alive(), 120.0)
        worker.join(30)
        assert done["state"] == "done", Dispatches(sessions).get(dispatch.id).error
        after = Dispatches(sessions).get(dispatch.id)
        assert after.verified is True
        posted = lib.derived_text(after.derived_id)
        # what the machine holds is the posted G-code, not the APT source
        assert "G01 X4. Y8. Z7. F10." in machine.memory.get(15)
        assert "GOTO" not in machine.memory.get(15)
        final_in, trace, cycle = run_seed15(machine, 15, tuple(G54_ROOM))
    finally:
        machine.close()
        engine.dispose()
    assert final_in == (4.0, 8.0, 6.0)
    check_seed15_trace(posted.splitlines(), trace, cycle)

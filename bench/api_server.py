"""The API benches' server: the real app over a library, on uvicorn, on an ephemeral
loopback port, in a thread of the bench process (shared by bench_api_*.py)."""

from __future__ import annotations

import socket
import threading


def serve_api(sessions, library, settings, backlog: int = 256):
    """Start the app; returns (app, server, thread, sock). Stop with `server.should_exit =
    True`, `thread.join()`, `sock.close()`."""
    import uvicorn

    from dnc.dispatch import Dispatches
    from dnc.jobs import Jobs
    from web_api.app import create_app

    app = create_app(
        settings,
        library=library,
        dispatches=Dispatches(sessions),
        jobs=Jobs(sessions),
        sessions=sessions,
    )
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    sock.listen(backlog)
    server = uvicorn.Server(
        uvicorn.Config(app, log_level="warning", timeout_graceful_shutdown=5, backlog=backlog)
    )
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    return app, server, thread, sock

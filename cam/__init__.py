"""CAM to machine: the APT processor, CL data and the post-processors (docs/cam.md).

The chain of 000_nc_book.md §11.3: part program (APT) -> processor -> CLDATA (tool-centre
locations, machine independent) -> post-processor (one per machine kind) -> NC program.
`cam` may import the NC kernel's kinematics, configuration and checker (`cnc`), nothing
above it.
"""

from cam.apt import process
from cam.cl import ClRecord, read_cl, write_cl
from cam.errors import CamError, CamWarning
from cam.post import Machine, PostOptions, load_machine, post, post_for, register_post

__all__ = [
    "CamError",
    "CamWarning",
    "ClRecord",
    "Machine",
    "PostOptions",
    "load_machine",
    "post",
    "post_for",
    "process",
    "read_cl",
    "register_post",
    "write_cl",
]

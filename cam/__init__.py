"""CAM to machine: the APT processor, CL data and the post-processors (docs/cam.md).

The chain of 000_nc_book.md §11.3: part program (APT) -> processor -> CLDATA (tool-centre
locations, machine independent) -> post-processor (one per machine kind) -> NC program.
`cam` may import the NC kernel's kinematics, configuration and checker (`cnc`), nothing
above it.
"""

"""A machine's faces: the ways a cell controller reaches a real CNC (DNC port, status, ...)."""

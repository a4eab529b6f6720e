"""DNC host: program library, transfer to machines and the FMS job queue."""

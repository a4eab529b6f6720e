"""DNC host: program library, transfer to machines and the FMS job queue."""

from cnc.config import HOST_CHECKS
from dnc.rules import rule_named

# the cell file's host.dispatch_rule is the host's key: checked at load by its owner
HOST_CHECKS["dispatch_rule"] = rule_named

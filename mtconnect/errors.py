"""The mtconnect package's one error root: every error it raises is an AgentError, so a
user of the agent alone catches one class. (Not named MTConnectError: that is the
standard's error document, which a RestError becomes.) The subclasses keep the builtin
base they had (ValueError for a path filter that cannot be read), so existing handlers
still see them."""

from __future__ import annotations


class AgentError(Exception):
    """Base of every error the mtconnect package raises (REST requests the agent refuses,
    path filters it cannot read)."""

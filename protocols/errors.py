"""The one error type of the wire.

Every failure to turn bytes (or a key expression) into a trusted object raises
:class:`ProtocolError` with a short machine-readable ``reason`` that services
count by, and a human message that says what was wrong.
"""

from __future__ import annotations

REASONS: dict[str, str] = {
    "malformed": "not a msgpack envelope of the expected layout",
    "oversize": "message or one of its parts exceeds a configured limit",
    "version": "unknown schema version for this kind",
    "kind": "unknown message kind",
    "field": "missing or unexpected field",
    "type": "field has the wrong type",
    "dtype": "array has a dtype that is not allowed here",
    "shape": "array shapes or batch sizes are inconsistent",
    "nonfinite": "NaN or infinity where a finite number is required",
    "action_range": "action outside [0, n_actions)",
    "range": "number outside its allowed range",
    "string": "string empty, too long or with characters not allowed",
    "key": "key expression or name that does not fit the navlearn key space",
}


class ProtocolError(ValueError):
    """Raised for any message or key that cannot be trusted.

    ``reason`` is one of :data:`REASONS` (a stable short code for counters);
    ``str(error)`` is ``"<reason>: <message>"``.
    """

    def __init__(self, reason: str, message: str) -> None:
        if reason not in REASONS:
            raise ValueError(f"unknown protocol error reason {reason!r}")
        self.reason = reason
        self.message = message
        super().__init__(f"{reason}: {message}")

    def __reduce__(self):  # keep it picklable across multiprocessing
        return (type(self), (self.reason, self.message))

"""The two kinds of failure a user can meet, kept apart on purpose.

* :class:`ConfigError` -- bad input. The CLI turns it into exit status 2 and ONE line on
  stderr naming the key, the value and what is allowed.
* :class:`ConvergenceError` -- a computation that did not converge. The CLI turns it into
  exit status 1; the message says where, what was tried and the residual reached.
"""

from __future__ import annotations

__all__ = ["ConfigError", "ConvergenceError"]


class ConfigError(ValueError):
    """Bad input: names the offending key, the value given and what is allowed.

    **Arguments:**

    - `key`: dotted config key, e.g. ``"gear.teeth_pinion"`` (or a CLI option such as
      ``"--speed"``).
    - `value`: the value that was given (shown with ``repr``).
    - `allowed`: a short phrase saying what is allowed, e.g. ``"an integer >= 5"``.
    """

    def __init__(self, key: str, value: object, allowed: str):
        self.key = key
        self.value = value
        self.allowed = allowed
        super().__init__(f"{key} = {value!r}: {allowed}")


class ConvergenceError(RuntimeError):
    """A solver did not converge; the message says where, what was tried and the residual."""

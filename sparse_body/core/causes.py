"""An error's causes: a signal raised inside compiled code comes back wrapped (numba's
dispatcher turns it into a SystemError whose cause is the original exception)."""

from __future__ import annotations


def cause_of_kind(err: BaseException | None, kind: type[BaseException] | tuple) -> BaseException | None:
    """The first of err and its causes (__cause__, else __context__) that is a `kind`."""
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, kind):
            return err
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None

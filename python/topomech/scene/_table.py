"""Reading a scene's TOML tables: :class:`_Table` (each getter checks a key's type and range
and names the key by its full path, ``integrator.dt``, ``model[1].kind``), :class:`_Fail`
(the :class:`SceneError` of a scene, ``FILE: KEY: problem``) and the checks of single values
every part of a scene uses: numbers, names, predicates.

The other modules of :mod:`topomech.scene` read their tables through these; this one imports
none of them.
"""

from __future__ import annotations

import difflib
import json
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any, overload

from topomech import _core
from topomech._core import RuleError, SceneError

#: The largest integer a scene key takes: a signed 64-bit integer (TOML's own range; Python's
#: reader accepts larger ones, which no count or index of a mesh reaches).
_INT_MAX = 2**63 - 1


def _too_large(v: int) -> str:
    """The message for an integer beyond :data:`_INT_MAX`."""
    return f"must be at most {_INT_MAX} (a 64-bit integer), got {v}"


def _show(value: Any) -> str:
    """A TOML value as a message shows it: strings quoted, booleans lowercase."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, (str, list)):
        try:
            return json.dumps(value)
        except (TypeError, ValueError):
            return repr(value)
    return str(value)


class _Table:
    """A TOML table being read: each getter checks a key's type and range and names the key
    by its full path; :meth:`done` refuses the keys nobody asked for."""

    def __init__(self, data: Mapping[str, Any], path: str, fail: _Fail) -> None:
        self.data = data
        self.path = path
        self.fail = fail
        self.known: list[str] = []

    def key(self, k: str) -> str:
        return f"{self.path}.{k}" if self.path else k

    def has(self, k: str) -> bool:
        return k in self.data

    def _get(self, k: str) -> Any:
        self.known.append(k)
        return self.data.get(k)

    @overload
    def number(
        self, k: str, default: float, *, positive: bool = ..., nonneg: bool = ...
    ) -> float: ...
    @overload
    def number(
        self, k: str, default: None = None, *, positive: bool = ..., nonneg: bool = ...
    ) -> float | None: ...
    def number(
        self,
        k: str,
        default: float | None = None,
        *,
        positive: bool = False,
        nonneg: bool = False,
    ) -> float | None:
        v = self._get(k)
        if v is None:
            return default
        return _number(v, self.key(k), self.fail, positive=positive, nonneg=nonneg)

    @overload
    def integer(self, k: str, default: int, *, minimum: int = ...) -> int: ...
    @overload
    def integer(self, k: str, default: None = None, *, minimum: int = ...) -> int | None: ...
    def integer(self, k: str, default: int | None = None, *, minimum: int = 0) -> int | None:
        v = self._get(k)
        if v is None:
            return default
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(self.key(k), f"expected an integer, got {_show(v)}")
        if v < minimum:
            raise self.fail(self.key(k), f"must be >= {minimum}, got {v}")
        if v > _INT_MAX:
            raise self.fail(self.key(k), _too_large(v))
        return v

    @overload
    def string(self, k: str, default: str) -> str: ...
    @overload
    def string(self, k: str, default: None = None) -> str | None: ...
    def string(self, k: str, default: str | None = None) -> str | None:
        v = self._get(k)
        if v is None:
            return default
        if not isinstance(v, str):
            raise self.fail(self.key(k), f"expected a string, got {_show(v)}")
        return v

    def choice(self, k: str, choices: Sequence[str], default: str) -> str:
        v = self.string(k, default)
        if v not in choices:
            raise self.fail(self.key(k), f"unknown value {_show(v)} (expected {_or(choices)})")
        return v

    @overload
    def vector(
        self, k: str, n: int, default: tuple[float, ...], *, positive: bool = ...
    ) -> tuple[float, ...]: ...
    @overload
    def vector(
        self, k: str, n: int, default: None = None, *, positive: bool = ...
    ) -> tuple[float, ...] | None: ...
    def vector(
        self, k: str, n: int, default: tuple[float, ...] | None = None, *, positive: bool = False
    ) -> tuple[float, ...] | None:
        v = self._get(k)
        if v is None:
            return default
        if not isinstance(v, list) or len(v) != n:
            raise self.fail(self.key(k), f"expected an array of {n} numbers, got {_show(v)}")
        return tuple(
            _number(x, f"{self.key(k)}[{i}]", self.fail, positive=positive) for i, x in enumerate(v)
        )

    def int_vector(self, k: str, n: int, default: tuple[int, ...]) -> tuple[int, ...]:
        v = self._get(k)
        if v is None:
            return default
        if not isinstance(v, list) or len(v) != n:
            raise self.fail(self.key(k), f"expected an array of {n} integers, got {_show(v)}")
        out = []
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, int):
                raise self.fail(f"{self.key(k)}[{i}]", f"expected an integer, got {_show(x)}")
            if x < 1:
                raise self.fail(f"{self.key(k)}[{i}]", f"must be >= 1, got {x}")
            if x > _INT_MAX:
                raise self.fail(f"{self.key(k)}[{i}]", _too_large(x))
            out.append(x)
        return tuple(out)

    def table(self, k: str) -> _Table:
        v = self._get(k)
        if v is None:
            v = {}
        if not isinstance(v, dict):
            raise self.fail(self.key(k), f"expected a table, got {_show(v)}")
        return _Table(v, self.key(k), self.fail)

    def tables(self, k: str) -> list[_Table]:
        """An array of tables (``[[k]]``); a single table ``[k]`` is refused, naming the
        double brackets."""
        v = self._get(k)
        if v is None:
            return []
        if isinstance(v, dict):
            raise self.fail(self.key(k), f"expected an array of tables: write [[{self.key(k)}]]")
        if not isinstance(v, list) or not all(isinstance(t, dict) for t in v):
            raise self.fail(self.key(k), f"expected an array of tables, got {_show(v)}")
        return [_Table(t, f"{self.key(k)}[{i}]", self.fail) for i, t in enumerate(v)]

    def done(self, extra: Sequence[str] = ()) -> None:
        """Refuses every key not read (nor in ``extra``), suggesting the closest known one."""
        known = [*self.known, *extra]
        for k in self.data:
            if k not in known:
                close = difflib.get_close_matches(k, known, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                if k in _SPELLED_ELSEWHERE and _SPELLED_ELSEWHERE[k][0] in known:
                    hint = f"; write {_SPELLED_ELSEWHERE[k][1]}"
                expected = f" (known: {', '.join(sorted(set(known)))})" if known else ""
                raise self.fail(self.key(k), f"unknown key{hint}{expected}")


#: Keys people write that a scene spells otherwise: the key, the key that is known where
#: this one is written, and the hint.
_SPELLED_ELSEWHERE = {
    "linear": ("order", 'order = "linear" (keep the corner nodes of second-order cells)'),
}


class _Fail:
    """Makes the :class:`SceneError` of a scene: ``FILE: KEY: problem``."""

    def __init__(self, source: str) -> None:
        self.source = source

    def __call__(self, key: str | None, problem: str) -> SceneError:
        where = f"{key}: " if key else ""
        err = SceneError(f"{self.source}: {where}{problem}")
        err.key = key
        err.source = self.source
        return err


class _ArgFail(_Fail):
    """A :class:`_Fail` for the arguments of the Python API (:class:`topomech.Simulation`):
    raises ``ValueError("KEY: problem")`` itself instead of making a :class:`SceneError`,
    so that a script's value is refused by the same check, with the same words, as a
    scene's."""

    def __init__(self) -> None:
        super().__init__("")

    def __call__(self, key: str | None, problem: str) -> SceneError:
        raise ValueError(f"{key}: {problem}" if key else problem)


#: The longest scene name, in UTF-8 bytes (a file name's limit on common file systems).
MAX_NAME_BYTES = 255


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot be a scene's name, or None when it can. The name is the output
    folder's name (``out/<name>``) and is shown in previews, so it must be one plain folder
    name: not empty, not ``.`` or ``..``, no path separator (``/``, ``\\``) or drive colon,
    no NUL or other control character, no leading or trailing blank, no leading ``-``, at most
    :data:`MAX_NAME_BYTES` bytes."""
    if not name:
        return "the name is empty"
    if name in (".", ".."):
        return f"{_show(name)} is not a folder name (it names a folder above or itself)"
    for ch in name:
        if ch in "/\\":
            return f"{_show(name)} contains a path separator {_show(ch)}: give a plain name"
        if ch == ":":
            return f"{_show(name)} contains ':' (a drive or stream separator): give a plain name"
        if ord(ch) < 32 or ord(ch) == 127:
            return f"{_show(name)} contains the control character U+{ord(ch):04X}"
    if not name.strip():
        return "the name is only blanks"
    if name != name.strip():
        return f"{_show(name)} begins or ends with a blank: a folder name that is easy to miss"
    if name.startswith("-"):
        return f"{_show(name)} begins with '-': a shell would read the folder as an option"
    if len(name.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES:
        return f"the name is longer than {MAX_NAME_BYTES} bytes"
    return None


def _number(
    v: Any, key: str, fail: _Fail, *, positive: bool = False, nonneg: bool = False
) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise fail(key, f"expected a number, got {_show(v)}")
    x = float(v)
    if not math.isfinite(x):
        raise fail(key, f"must be finite, got {_show(v)}")
    if positive and x <= 0:
        raise fail(key, f"must be positive, got {_show(v)}")
    if nonneg and x < 0:
        raise fail(key, f"must be >= 0, got {_show(v)}")
    return x


def _or(items: Sequence[str]) -> str:
    items = [f"'{i}'" for i in items]
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} or {items[-1]}"


_DIAGNOSTIC = re.compile(r"^.*?:(\d+):(\d+): error\[([\w-]+)\]: (?:rule '\w+': )?(.*)$")


def _check_predicate(pred: str, key: str, fail: _Fail) -> str:
    """Checks a predicate the way the kernel will compile it (one expression of the rule
    language over ``x``, ``y``, ``z``, the guard of a rule built around it, never rule text),
    so that a bad one is named by its key and the place in it (line and column)."""
    if not pred.strip():
        raise fail(key, "the predicate is empty")
    try:
        _core.check_predicate(pred, key)
    except RuleError as e:
        problems = []
        for line in e.diagnostics:
            m = _DIAGNOSTIC.match(line)
            if m is None:
                problems.append(line)
                continue
            row, col = int(m.group(1)), int(m.group(2))
            at = f"line {row}, column {col}" if row > 1 else f"column {col}"
            problems.append(f"{at}: {m.group(4)}")
        raise fail(key, f"bad predicate {_show(pred)}: {'; '.join(problems)}") from None
    return pred


def _required_str(t: _Table, k: str, fail: _Fail) -> str:
    v = t.string(k)
    if v is None:
        raise fail(t.key(k), "missing")
    return v

"""JSON text from files tofnet did not necessarily write, parsed into one-line errors.

``json.loads`` raises three kinds of exception on hostile text, and a caller catching only
``JSONDecodeError`` let the other two out as tracebacks: ``JSONDecodeError`` (not JSON),
``ValueError`` (an integer of more than 4300 digits, which Python refuses to convert since
3.11) and ``RecursionError`` (brackets nested thousands deep). Every JSON file tofnet reads
goes through ``parse_json``.
"""

from __future__ import annotations

import json

from tofnet.errors import DataError, located, reason


def parse_json(text: str, where: object, what: str = "") -> object:
    """``json.loads(text)``, else a one-line ``DataError`` naming ``where`` (a path) and ``what`` (the field
    holding the text, e.g. ``summary_json``; empty when the file is the JSON)."""
    field = f"{what} is " if what else ""
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        problem = f"{field}not valid JSON ({err.msg}, line {err.lineno} column {err.colno})"
    except ValueError as err:  # a number Python will not convert
        problem = f"{field}not readable JSON ({reason(err)})"
    except RecursionError:
        problem = f"{field or 'the JSON is '}nested too deeply"
    raise DataError(located(where, None, problem))

"""Records kept beside a phase for the inputs and settings they were made for: a search
done before sampling (SP's start, SPix1's rescan) is written with a fingerprint and read
back instead of redone when the phase runs again on the same fingerprint."""

import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from mgelens.atomic import write_json

Record = TypeVar("Record")


def read_or_make(
    path: Path,
    key: str,
    fingerprint: dict,
    make: Callable[[], Record],
    from_dict: Callable[[dict], Record],
    logger: logging.Logger,
    label: str,
) -> Record:
    """The record under ``key`` in the JSON file ``path`` if it was made for
    ``fingerprint``, else ``make()``'s, written to ``path`` atomically with the
    fingerprint (``record.to_dict()``). An unreadable file or another fingerprint is
    logged (to ``logger``, naming the ``label``) and the record made again."""
    fingerprint = json.loads(json.dumps(fingerprint))  # as read back from JSON
    if path.is_file():
        try:
            content = json.loads(path.read_text())
            recorded = from_dict(content[key])
        except (ValueError, KeyError, TypeError) as error:
            logger.warning("%s unreadable (%s): %s again", path, error, label)
        else:
            if content.get("fingerprint") == fingerprint:
                logger.info("%s read from %s", label, path)
                return recorded
            logger.info("%s was made for other inputs or settings: %s again", path, label)
    record = make()
    write_json(path, {key: record.to_dict(), "fingerprint": fingerprint})
    return record

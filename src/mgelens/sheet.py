"""Sample sheets: one tab-separated row per lens under a header line (README
"Configurations"; columns in ``workflow/schemas/lenses.schema.yaml``).

:func:`read_sample_sheet` reads a sheet for the workflow (``workflow/rules/common.smk``,
which validates its rows against the schema) and refuses, naming the sheet and the line
where there is one, what pandas would read wrongly or not at all.
"""

from pathlib import Path

import pandas as pd


class SheetError(ValueError):
    """An unreadable sample sheet; the message names the sheet and the fix."""


STRING_COLUMNS = ("lens", "mock", "input", "lens_light", "contaminants")
"""Columns read as text whatever they hold (a lens id ``1`` stays "1")."""


def read_sample_sheet(path: str | Path) -> pd.DataFrame:
    """The sample sheet at ``path``, indexed by lens id (the ``lens`` column, kept).

    ``#`` starts a comment. Only empty cells are missing values: an id such as ``nan`` or
    ``NA`` is read as written.

    Raises
    ------
    SheetError
        For an empty file, a row with more cells than the header has columns (naming the
        line), no ``lens`` column, no lens row, or repeated lens ids.
    """
    path = Path(path)
    check_row_widths(path, path.read_text())
    sheet = pd.read_csv(
        path,
        sep="\t",
        comment="#",
        dtype=dict.fromkeys(STRING_COLUMNS, str),
        keep_default_na=False,
        na_values=[""],
    )
    if "lens" not in sheet.columns:
        raise SheetError(
            f"sample sheet {path} has no `lens` column (columns read: {list(sheet.columns)}); "
            "the sheet is tab-separated with a header line, see config/lenses.tsv"
        )
    if sheet.empty:
        raise SheetError(
            f"sample sheet {path} lists no lens: add one tab-separated row per lens under "
            "its header line, see config/lenses.tsv"
        )
    duplicated = sheet["lens"][sheet["lens"].duplicated()].tolist()
    if duplicated:
        raise SheetError(f"{path}: lens ids must be unique, repeated: {duplicated}")
    if "mge_sets" in sheet.columns and not pd.api.types.is_numeric_dtype(sheet["mge_sets"]):
        sheet["mge_sets"] = sheet["mge_sets"].map(_integer_or_word).astype(object)
    return sheet.set_index("lens", drop=False)


def _integer_or_word(cell):
    """A cell of a column mixing integers and words (``mge_sets``: 2 or ``auto``) as an
    int where it is written as one, else as written; pandas reads such a column as text."""
    if isinstance(cell, str) and cell.strip().isdigit():
        return int(cell)
    return cell


def check_row_widths(path: Path, text: str) -> None:
    """Raise :class:`SheetError` if ``text`` (the sheet at ``path``) has no header line or
    a row with more cells than the header has columns: pandas would take the first column
    as an index and shift every column, or stop without naming the sheet."""
    lines = enumerate(text.splitlines(), start=1)
    rows = [(n, line.split("#")[0]) for n, line in lines if line.split("#")[0].strip()]
    if not rows:
        raise SheetError(
            f"sample sheet {path} is empty: it needs a tab-separated header line and one row "
            "per lens, see config/lenses.tsv"
        )
    header = rows[0][1].split("\t")
    for n, row in rows[1:]:
        cells = row.split("\t")
        if len(cells) > len(header):
            raise SheetError(
                f"sample sheet {path}, line {n}: {len(cells)} cells but the header has "
                f"{len(header)} columns ({', '.join(header)}); remove the extra cell (a stray "
                "tab?) or add its column to the header"
            )

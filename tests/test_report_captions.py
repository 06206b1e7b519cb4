"""Every report caption (``workflow/report/*.rst``) renders without a docutils warning:
``snakemake --report`` passes captions through docutils, which reads ``|x|`` as an
undefined substitution and prints an error into the report instead of the text."""

import io
from pathlib import Path

import docutils.core
import pytest

CAPTIONS = sorted((Path(__file__).resolve().parents[1] / "workflow" / "report").glob("*.rst"))


def docutils_warnings(text: str) -> str:
    stream = io.StringIO()
    docutils.core.publish_parts(
        text, writer="html", settings_overrides={"warning_stream": stream, "report_level": 2}
    )
    return stream.getvalue()


def test_an_absolute_value_bar_is_reported():
    assert "Undefined substitution" in docutils_warnings("the largest |a4/a| per lens")


@pytest.mark.parametrize("caption", CAPTIONS, ids=lambda path: path.name)
def test_the_caption_renders_without_warnings(caption):
    assert docutils_warnings(caption.read_text()) == ""

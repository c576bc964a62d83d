"""Text in the pictures: what a user wrote is drawn as written, and within bounds.

Titles, descriptions, units, part names, file names and sweep keys and values come from
files a user wrote, or from result files anyone with write access to a results
directory may have changed. matplotlib reads a pair of ``$`` in a text as mathtext (and
fails on ``load $\\frac{$ case``), and lays out a text of 10 MB for minutes.

Two rules, applied by every picture of the package:

- every figure is written through :func:`save_png`, which first passes it through
  :func:`literal`: each of its texts (titles, suptitles, axis labels, legend entries,
  annotations, colour-bar and scale-bar labels) is drawn as plain text
  (``parse_math=False``, no TeX) and cut to :data:`TEXT_CHARS` characters. Only tick
  labels and axis offsets, the numbers matplotlib's formatters write, keep mathtext;
- a user's string is put into a text through :func:`shown` (one line) or :func:`heading`
  (wrapped over a few lines), which replace control characters and cut it to a readable
  length with an ellipsis, before it is copied anywhere.
"""

from __future__ import annotations

import textwrap
import unicodedata
import warnings
from pathlib import Path

#: A user's string is shown with at most this many characters (then an ellipsis).
USER_CHARS = 200
#: A heading (a title) is wrapped at this many characters a line, over at most HEADING_LINES lines.
HEADING_WIDTH = 100
HEADING_LINES = 2
#: No text of a figure is drawn longer than this (a bound on layout time, whatever the source).
TEXT_CHARS = 2000
ELLIPSIS = "…"
_REPLACEMENT = "\ufffd"


def shown(value: object, limit: int = USER_CHARS) -> str:
    """``value`` as one line of at most ``limit`` characters: tabs and line breaks as spaces,
    other control characters and lone surrogates (an undecodable file name) as U+FFFD, and
    the end beyond ``limit`` cut off with an ellipsis.

    Only the first ``limit + 1`` characters are looked at: a string of megabytes costs no more
    than a short one.
    """
    text = value if isinstance(value, str) else str(value)
    cut = len(text) > limit
    text = text[: limit + 1]
    characters = []
    for character in text:
        if character in "\t\n\r\v\f":
            characters.append(" ")
        elif unicodedata.category(character) in ("Cc", "Cs"):
            characters.append(_REPLACEMENT)
        else:
            characters.append(character)
    text = "".join(characters)
    if cut:
        text = text[: max(limit - 1, 0)].rstrip() + ELLIPSIS
    return text


def heading(value: object, width: int = HEADING_WIDTH, lines: int = HEADING_LINES) -> str:
    """``value`` (:func:`shown`) wrapped at ``width`` characters over at most ``lines`` lines,
    the rest cut off with an ellipsis; a word longer than a line is broken."""
    text = shown(value, limit=width * lines)
    if len(text) <= width:
        return text
    return "\n".join(textwrap.wrap(text, width=width, max_lines=lines, placeholder=" " + ELLIPSIS,
                                   break_on_hyphens=False)) or text[:width]


def chars_across(width_pixels: float, fontsize: float, dpi: float = 100) -> int:
    """About how many characters of ``fontsize`` points fit across ``width_pixels`` (at least 20):
    the wrapping width of a heading in a figure of that width."""
    average = 0.6 * fontsize * dpi / 72  # DejaVu Sans: an average character is about 0.6 em wide
    return max(20, int(width_pixels / average))


def _bounded(text: str, limit: int) -> str:
    """A figure's own text cut to ``limit`` characters (line breaks kept)."""
    return text if len(text) <= limit else text[: limit - 1] + ELLIPSIS


def _texts(artist):
    """Every Text artist under ``artist`` except tick labels and axis offset texts."""
    from matplotlib.axis import Axis
    from matplotlib.text import Text

    if isinstance(artist, Axis):
        yield artist.label  # the ticks and the offset (e.g. ×10⁻³) are the formatters' numbers
        return
    if isinstance(artist, Text):
        yield artist
    for child in artist.get_children():
        yield from _texts(child)


def literal(figure, limit: int = TEXT_CHARS) -> int:
    """Make every text of ``figure`` (tick labels and axis offsets aside) plain text of at most
    ``limit`` characters; returns how many texts there are.

    Call it after the figure is complete and before it is laid out (``tight_layout``
    measures the texts) or saved; :func:`save_png` does both in that order.
    """
    count = 0
    for text in _texts(figure):
        text.set_usetex(False)
        text.set_parse_math(False)
        content = text.get_text()
        if len(content) > limit:
            text.set_text(_bounded(content, limit))
        count += 1
    return count


def save_png(figure, path: Path | str, dpi: float = 110, layout: dict | None = None) -> Path:
    """Write ``figure`` as the PNG ``path``, atomically, its texts drawn literally (:func:`literal`).

    ``layout``: keyword arguments of ``figure.tight_layout``, run after the texts are made
    literal (None: the figure is laid out already). A failed write is an
    :class:`~contactfem.errors.OutputError`.
    """
    from contactfem.errors import OutputError
    from contactfem.io.atomic import atomic_path

    path = Path(path)
    literal(figure)
    with warnings.catch_warnings():
        # A character the font has no glyph for (a title in a script DejaVu Sans lacks)
        # is drawn as a box; saying so for every one of them on stderr says nothing more.
        warnings.filterwarnings("ignore", message=r"Glyph \d+ .*missing from", category=UserWarning)
        warnings.filterwarnings("ignore", message=r"Matplotlib currently does not support", category=UserWarning)
        if layout is not None:
            figure.tight_layout(**layout)
        try:
            with atomic_path(path) as temporary:
                figure.savefig(temporary, format="png", dpi=dpi)
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path

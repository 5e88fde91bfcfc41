"""``bomgraph.cli.main`` in its caller's process gives back the caller's logging and warnings
(its ``-q`` left the root logger at ERROR with the caller's handlers removed, and every
warning ignored, for the rest of the process: a later test's ``caplog`` on another logger then
saw nothing)."""

from __future__ import annotations

import logging
import warnings

from bomgraph.cli import main


def test_main_restores_the_callers_root_logger_and_warnings(capsys) -> None:
    root = logging.getLogger()
    mine = logging.StreamHandler()
    root.addHandler(mine)
    level = root.level
    root.setLevel(logging.DEBUG)
    showwarning = warnings.showwarning
    try:
        assert main(["methods", "-q"]) == 0
        assert main(["methods", "-v"]) == 0
        assert root.level == logging.DEBUG
        assert mine in root.handlers and not mine.stream.closed
        assert all(not (h.formatter and "bomgraph:" in (h.formatter._fmt or ""))
                   for h in root.handlers)
        # -q's warnings.simplefilter("ignore") (modules imported meanwhile may add their own)
        assert ("ignore", None, Warning, None, 0) not in warnings.filters
        assert warnings.showwarning is showwarning
    finally:
        root.removeHandler(mine)
        root.setLevel(level)
    capsys.readouterr()


def test_the_callers_capture_of_warnings_works_after_main(capsys) -> None:
    """main()'s logging.captureWarnings(True) was undone by putting showwarning back, while
    logging still held the function it had replaced: the caller's own
    logging.captureWarnings(True) afterwards did nothing (its warnings went to stderr, not to
    its logging), and a second main() in the process printed warnings unformatted."""
    showwarning = warnings.showwarning
    try:
        assert main(["methods"]) == 0
        assert warnings.showwarning is showwarning
        logging.captureWarnings(True)
        assert warnings.showwarning is not showwarning  # warnings now go to logging
        logging.captureWarnings(False)
        assert warnings.showwarning is showwarning
    finally:
        logging.captureWarnings(False)
        warnings.showwarning = showwarning
    capsys.readouterr()

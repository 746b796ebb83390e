"""Warnings held, then shown once (:func:`ident.held_warnings.warnings_held`, the one helper of
``jointid fit``/``export-model`` and of the robot MCAP loader): each distinct warning of the
block is shown once, in order, when it ends normally or by an interrupt; none when it ends in
an error (a refusal is its one line); the caller's filters apply where each is raised.

Before the helper, ``ident.cli.warnings_held`` lost the warnings of a block ended by Ctrl-C
(its docstring said "shown"; :func:`test_interrupt_loses_nothing` fails on it), and the
loader kept a second copy with other filter and output rules.
"""

from __future__ import annotations

import warnings

import pytest

from ident.held_warnings import warnings_held


class DriveWarning(UserWarning):
    pass


def _raise_some() -> None:
    warnings.warn("chunk at offset 10 damaged", RuntimeWarning, stacklevel=1)
    warnings.warn("truncated run log", RuntimeWarning, stacklevel=1)
    warnings.warn("chunk at offset 10 damaged", RuntimeWarning, stacklevel=1)  # another line
    warnings.warn("chunk at offset 10 damaged", DriveWarning, stacklevel=1)  # another kind


def _shown(block) -> list[tuple[str, type[Warning]]]:
    """The warnings shown by ``block()`` (run under an ``always`` filter), as shown."""
    with warnings.catch_warnings(record=True) as log:
        warnings.simplefilter("always")
        block()
    return [(str(w.message), w.category) for w in log]


EXPECTED = [("chunk at offset 10 damaged", RuntimeWarning),
            ("truncated run log", RuntimeWarning),
            ("chunk at offset 10 damaged", DriveWarning)]


def test_each_warning_shown_once_in_order():
    def block():
        with warnings_held():
            _raise_some()
            _raise_some()
    assert _shown(block) == EXPECTED


def test_held_until_the_block_ends():
    during: list[int] = []

    def block():
        with warnings.catch_warnings(record=True) as outer:
            warnings.simplefilter("always")
            with warnings_held():
                _raise_some()
                during.append(len(outer))
            during.append(len(outer))
    _shown(block)
    assert during == [0, 3]


def test_nested_blocks_show_once():
    """The loader's block inside ``jointid fit``'s: each warning once, at the outer end."""
    def block():
        with warnings_held():
            with warnings_held():
                _raise_some()
            with warnings_held():
                _raise_some()
    assert _shown(block) == EXPECTED


@pytest.mark.parametrize("stop", [KeyboardInterrupt, SystemExit])
def test_interrupt_loses_nothing(stop):
    def block():
        with pytest.raises(stop), warnings_held():
            _raise_some()
            raise stop()
    assert _shown(block) == EXPECTED


def test_refusal_is_said_alone():
    def block():
        with pytest.raises(ValueError, match="too few samples"), warnings_held():
            _raise_some()
            raise ValueError("too few samples")
    assert _shown(block) == []


def test_the_callers_filters_apply():
    def ignored():
        with warnings_held():
            warnings.simplefilter("ignore", RuntimeWarning)  # inside: restored at the end
            _raise_some()
    assert _shown(ignored) == [("chunk at offset 10 damaged", DriveWarning)]

    def outer_ignore():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DriveWarning)
            with warnings_held():
                _raise_some()
    assert _shown(outer_ignore) == EXPECTED[:2]

    def as_error():
        with warnings.catch_warnings():
            warnings.simplefilter("error", DriveWarning)
            with pytest.raises(DriveWarning), warnings_held():
                _raise_some()
    assert _shown(as_error) == []  # raised where it was warned: an error, the others dropped


def test_filters_and_showwarning_given_back():
    before = (warnings.filters[:], warnings.showwarning)
    with warnings_held():
        warnings.simplefilter("ignore")
        _raise_some()
    assert (warnings.filters, warnings.showwarning) == before

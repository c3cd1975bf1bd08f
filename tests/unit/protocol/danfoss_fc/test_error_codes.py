"""AK 7 error codes (protocols/danfoss-fc.md §6.6): PWElow is a binary integer."""

from __future__ import annotations

import pytest

from fcmaster.protocol.danfoss_fc import ERROR_CODES, error_text


@pytest.mark.parametrize(
    ("code", "words"),
    [
        pytest.param(0, ("parameter",), id="0-illegal-parameter"),
        pytest.param(2, ("limit",), id="2-limit"),
        pytest.param(11, ("write access",), id="11-no-write-access"),
        pytest.param(17, ("running",), id="17-printed-11-in-hex-tables"),
        pytest.param(130, ("bus access",), id="130-printed-82-in-hex-tables"),
        pytest.param(131, ("factory",), id="131-printed-83-in-hex-tables"),
        pytest.param(253, ("not supported",), id="253-request-not-supported"),
        pytest.param(255, ("no error",), id="255-no-error"),
    ],
)
def test_error_texts_say_what_the_manual_says(code: int, words: tuple[str, ...]) -> None:
    text = error_text(code).lower()
    assert all(word in text for word in words), text


def test_hex_printed_codes_are_not_read_as_decimal() -> None:
    # 0x11 on the wire is 17 ("not while running"), not 11 ("no write access").
    assert error_text(0x11) == error_text(17) != error_text(11)
    assert error_text(0x82) == error_text(130)


def test_unlisted_code_gets_a_text_with_its_number() -> None:
    assert 101 not in ERROR_CODES
    assert "101" in error_text(101)

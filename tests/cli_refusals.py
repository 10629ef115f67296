"""How the `gcs` command refuses bad input, checked on the result of one invocation
(`tests/conftest.py`'s `gcs_main`): one line on stderr, nothing on stdout, exit 2."""

from __future__ import annotations


def one_line_exit_2(result, *names: str) -> None:
    code, out, err = result
    assert code == 2, err
    assert out == ""
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    for name in names:
        assert name in err

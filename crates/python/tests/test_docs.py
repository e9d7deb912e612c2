"""Every public object's docstring example runs and prints what it says."""

import doctest

import pytest

import mfm
import mfm.torch

OBJECTS = [getattr(mfm, name) for name in mfm.__all__ if name != "__version__"]


@pytest.mark.parametrize("obj", OBJECTS + [mfm, mfm.torch], ids=lambda o: getattr(o, "__name__", str(o)))
def test_docstring_examples_run(obj):
    doc = obj.__doc__ or ""
    assert ">>>" in doc, f"{obj!r} has no example"
    test = doctest.DocTestParser().get_doctest(doc, {}, getattr(obj, "__name__", "mfm"), None, 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0

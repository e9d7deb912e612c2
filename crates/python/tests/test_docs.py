"""Every public object's docstring example runs and prints what it says."""

import doctest

import pytest

import mfm
from conftest import need

OBJECTS = [getattr(mfm, name) for name in mfm.__all__ if name != "__version__"] + [mfm]


def run_examples(obj):
    doc = obj.__doc__ or ""
    assert ">>>" in doc, f"{obj!r} has no example"
    name = getattr(obj, "__name__", "mfm")
    test = doctest.DocTestParser().get_doctest(doc, {}, name, None, 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    assert runner.summarize(verbose=False).failed == 0


@pytest.mark.parametrize("obj", OBJECTS, ids=lambda o: getattr(o, "__name__", str(o)))
def test_docstring_examples_run(obj):
    run_examples(obj)


def test_the_torch_module_example_runs():
    need("torch")
    import mfm.torch

    run_examples(mfm.torch)

"""Session hooks. The bounds-checked kernel run of tests/test_boundscheck.py, the longest test
(it compiles every kernel again, in a process of its own), starts as soon as the tests are
collected and its test is moved to the end of the run: the compilation then runs on the
machine's second core while the rest of the suite runs on the first (CI has two cores)."""

import shutil
import tempfile

import pytest

BOUNDSCHECK_TEST = "test_boundscheck.py::test_kernels_stay_in_bounds"
_RUN = pytest.StashKey()


def pytest_collection_modifyitems(session, config, items):
    """Start the bounds-checked run if its test was collected, and run that test last."""
    chosen = [item for item in items if item.nodeid.endswith(BOUNDSCHECK_TEST)]
    if not chosen or config.option.collectonly:
        return
    import test_boundscheck

    cache_dir = tempfile.mkdtemp(prefix="slipstep-boundscheck-")
    config.stash[_RUN] = (test_boundscheck.start(cache_dir), cache_dir)
    items[:] = [item for item in items if item not in chosen] + chosen


def pytest_unconfigure(config):
    """Stop the bounds-checked run if the session ended before its test (-x, Ctrl-C)."""
    run = config.stash.get(_RUN, None)
    if run is not None:
        process, cache_dir = run
        if process.poll() is None:
            process.kill()
            process.wait()
        shutil.rmtree(cache_dir, ignore_errors=True)


@pytest.fixture
def boundscheck_run(request):
    """(process, directory) of the bounds-checked run started by the hook above."""
    run = request.config.stash.get(_RUN, None)
    assert run is not None, "the bounds-checked run was not started (tests/conftest.py)"
    return run

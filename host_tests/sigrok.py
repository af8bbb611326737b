"""sigrok-cli for the tests that decode traces with it: skipped with the reason where it
is missing, unless MIXSTEP_REQUIRE_ALL=1 (as CI sets), where that is a failure."""
import os
import shutil

import pytest


def need_sigrok():
    if shutil.which("sigrok-cli"):
        return
    reason = "sigrok-cli is not installed (apt-get install sigrok-cli; .ci/run installs it)"
    if os.environ.get("MIXSTEP_REQUIRE_ALL") == "1":
        pytest.fail(reason + " (MIXSTEP_REQUIRE_ALL=1 asks for every test to run)")
    pytest.skip(reason)

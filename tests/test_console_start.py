"""A signal while the console script is still importing ends it in one line, never a traceback
(bad_input_battery's SIGINT at 1.5 s on a busy machine landed in an import: exit 130 with Python's
traceback)."""

import signal
import subprocess
import sys
import time

import pytest


@pytest.mark.parametrize("delay", [0.05, 0.15, 0.3])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_start_up_is_one_line(tmp_path, delay, sig):
    cmd = [sys.executable, "-m", "wingopt", "modes", "membrane", "--count", "3", "--json"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    time.sleep(delay)
    p.send_signal(sig)
    out, err = p.communicate(timeout=60)
    before_wingopt = "init_import_site" in err or (p.returncode == -sig and not err)
    frames = [line for line in err.splitlines() if line.strip().startswith("File ")]
    before_wingopt |= "Traceback" in err and not any("/wingopt/" in line for line in frames)
    if before_wingopt:
        # a loaded machine: the signal came while Python itself was starting (site packages, runpy's
        # import machinery, the editable install's finder: no frame in the package, so no handler of
        # its could be installed yet):
        # Python's default action, and nothing written
        assert not any(tmp_path.iterdir())
        return
    assert "Traceback" not in err, err
    if p.returncode != 0:  # the run may have finished before the signal on a fast machine
        assert p.returncode == 128 + sig, (p.returncode, err)
        assert len(err.strip().splitlines()) == 1 and "nothing written" in err, err

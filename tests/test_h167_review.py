"""Review of h161 (h167): a refused bearing sigma just above pi shown apart from pi, and the
fast refusal of a scheduler address kept off a scheduler that is only slow to answer."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from bomgraph.cli import main


def _with_bearing_sigma(tmp_path: Path, sigma: float) -> Path:
    s = tmp_path / "s.jsonl"
    assert main(["simulate", "--seed", "1", "--steps", "20", "--out", str(s), "-q"]) == 0
    lines = [json.loads(ln) for ln in s.read_text().splitlines()]
    lines[0]["bearing_sigma_rad"] = sigma
    bad = tmp_path / "bad.jsonl"
    bad.write_text("".join(json.dumps(o) + "\n" for o in lines))
    return bad


@pytest.mark.parametrize("method", ["stmds-smacof", "gtsam-batch", "ekf"])
def test_a_bearing_sigma_just_above_pi_is_shown_above_it(
        tmp_path: Path, method: str, capsys: pytest.CaptureFixture) -> None:
    """3.1415927 rad was refused as "a bearing std. dev. of 3.14159 rad: it must be in
    (0, pi]", a value that reads as inside the bound (as h161 mended for a far move)."""
    bad = _with_bearing_sigma(tmp_path, 3.1415927)
    capsys.readouterr()
    assert main(["run", str(bad), "--method", method, "--out", str(tmp_path / "e.est"),
                 "--allow-truth", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert (f"bad.jsonl, line 1: 'bearing_sigma_rad': {method} cannot use a bearing std. dev. "
            f"of 3.141593 rad: it must be in (0, pi]") in err[0]


def test_shown_beyond_keeps_short_values_short() -> None:
    import math

    from bomgraph.method_limits import shown_beyond

    assert shown_beyond(4.0, math.pi) == "4"
    assert shown_beyond(1e9 + 1, 1e9) == "1000000001"
    assert float(shown_beyond(math.nextafter(math.pi, 4), math.pi)) > math.pi


def test_a_scheduler_slow_to_answer_is_still_used() -> None:
    """h161 tries the address itself once Dask's connect has taken
    :data:`~bomgraph.cluster.PROBE_AFTER_S`: a real scheduler whose event loop is busy for
    longer than that (2 s here) still answers, and is used, not refused."""
    pytest.importorskip("distributed")
    from distributed import LocalCluster

    from bomgraph import cluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
                      host="127.0.0.1", dashboard_address=None,
                      scheduler_kwargs=cluster.LOCAL_SCHEDULER_HTTP) as local:
        local.loop.add_callback(time.sleep, 4 * cluster.PROBE_AFTER_S)   # busy, not gone
        time.sleep(0.1)   # (the sleep has started: not a timing assertion)
        assert cluster.check_scheduler(local.scheduler_address, 30) == 1


@pytest.mark.parametrize("method", ["triangulate", "gtsam-isam2"])
def test_a_near_start_pose_is_not_named_for_a_far_move(tmp_path: Path, method: str,
                                                       capsys: pytest.CaptureFixture) -> None:
    """``--option start_pose=[1,0,0]`` and a step's move of 2e9 m: the refusal said "fix the
    stream's odometry, or the option start_pose: it starts the robot 1 m from the map origin",
    a start that no value could mend. It is named where the odometry alone stays within the
    bound (a start 6e8 m out and a move of 6e8 m)."""
    s = _with_bearing_sigma(tmp_path, 0.01)
    lines = [json.loads(ln) for ln in s.read_text().splitlines()]

    def refusal(start: str, move: float) -> str:
        lines[5]["odom"] = [move, 0.0, 0.0]
        far = tmp_path / "far.jsonl"
        far.write_text("".join(json.dumps(o) + "\n" for o in lines))
        capsys.readouterr()
        assert main(["run", str(far), "--method", method, "--option", f"start_pose={start}",
                     "--out", str(tmp_path / "e.est"), "--allow-truth", "-q"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "line 6: 'odom': step 4: " in err[0], err
        return err[0]

    line = refusal("[1,0,0]", 2e9)
    assert "beyond 1e+09 m" in line and "option start_pose" not in line, line
    line = refusal("[6e8,0,0]", 6e8)
    assert ("fix the stream's odometry, or the option start_pose: it starts the robot 6e+08 m "
            "from the map origin") in line, line


def test_a_scheduler_that_starts_beside_the_command_is_used(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``dask scheduler & bomgraph compare --scheduler ...``: the scheduler listens a second
    or so after the command asks. h161's probe refused the first refusal it met (after 0.5 s),
    where Dask's connect would have waited for it; refusals are now tried again for
    :data:`~bomgraph.cluster.REFUSED_GRACE_S`. Here the scheduler opens its port 3 probes
    after the check began (the check's outcome is asserted, not its time)."""
    pytest.importorskip("distributed")
    import socket
    import threading

    from distributed import LocalCluster

    from bomgraph import cluster

    monkeypatch.setattr(cluster, "REFUSED_GRACE_S", 60.0)   # a loaded machine's slow start
    with socket.socket() as s:               # a free port, closed again: refused until used
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    started = threading.Event()
    stop = threading.Event()

    def later() -> None:
        time.sleep(3 * cluster.PROBE_AFTER_S)
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                          protocol="tcp://", host="127.0.0.1", scheduler_port=port,
                          dashboard_address=None,
                          scheduler_kwargs=cluster.LOCAL_SCHEDULER_HTTP):
            started.set()
            stop.wait(60)

    t = threading.Thread(target=later, daemon=True)
    t.start()
    try:
        assert cluster.check_scheduler(f"tcp://127.0.0.1:{port}", 30) >= 0
        assert started.is_set()
    finally:
        stop.set()
        t.join(30)

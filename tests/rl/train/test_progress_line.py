"""Training progress says how far the run is: steps of the total, the rate and the time left."""

import re

from dtradar_rl.cli import main


def test_the_progress_line_gives_the_total_the_rate_and_the_time_left(tmp_path, capsys):
    argv = ["train", "--scene", "synthetic-6x5", "--total-env-steps", "2000", "--num-envs", "16", "--hidden", "16"]
    assert main([*argv, "--learning-starts", "500", "--out", str(tmp_path), "--threads", "1"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("[")]
    assert lines and all(re.search(r"steps +\d+/2000 \( *\d+ %, [\d ]+ steps/s, ~\d+ s left\)", x) for x in lines)
    assert "~0 s left" in lines[-1]  # a run of seconds counts down in seconds

"""The speed page's tables of ``make bench-rl``'s other runs (``--env-only``, ``--no-robust --name ...``): each
renderer gives the committed page's block back from a JSON holding its numbers, and a re-run's number lands in it."""


def test_the_env_only_run_renders_the_throughput_table_with_the_fastest_in_bold(pages, tmp_path, capsys):
    data = {
        "config": {"env_only": True, "threads": 1, "env_threads": [1, 2]},
        "dataset": {"name": "cubicle/blueprint", "synthetic": False},
        "machine": {"torch_threads": 1, "load_1min_before": 0.0},
        "env_steps_per_s": {
            "gymnasium": 48_312.0,
            "batched_1": 17_391.0,
            "batched_general_1": 9_604.0,
            "batched_1_t2": 14_122.0,
            "batched_256": 2_831_000.0,
            "batched_general_256": 1_309_000.0,
            "batched_256_t2": 2_894_000.0,
            "batched_4096": 17_290_000.0,
            "batched_general_4096": 6_991_000.0,
            "batched_4096_t2": 16_120_000.0,
        },
    }
    change = ("9604.0", "999")  # a number that prints as it is
    pages.renders_the_page(tmp_path, capsys, "speed.md", "speed-env", data, change)
    md = pages.results_pages.bench("bench_rl_report.py", "env_table")(data)
    assert "| 1 | 17.4 K | 9.6 K | 14.1 K | 48.3 K |" in md


def _row(case: str, success: float, spl: float) -> dict:
    return {"case": case, "pairs": 500, "success_rate": success, "spl": spl, "collisions": 0.0}


def test_a_no_robust_run_of_its_own_name_renders_the_memory_agent_against_sb3(pages, tmp_path, capsys):
    bp, dyn = "cubicle/blueprint", "cubicle/dynamic"
    data = {
        "config": {"budget": 600_000, "sb3_max_seconds": 300.0, "robust": False, "name": "bench_rl_memory"},
        "dataset": {"name": bp, "synthetic": False},
        "machine": {"torch_threads": 2, "load_1min_before": 0.0},
        "train": {"env_steps": 600_064, "updates": 12_293, "wall_s": 77.31},
        "train_robust": None,
        "train_default": {"config": {"preset": "memory-escape-noise"}, "updates": 12_293, "wall_s": 135.98},
        "sb3": {
            "env_steps": 289_821,
            "wall_s": 289.9,
            "capped": True,
            "wall_s_for_budget": 621.2,
            "threads": 2,
            "blueprint": _row("sb3", 0.996, 0.993),
            "dynamic": _row("sb3", 0.706, 0.700),
        },  # fmt: skip
        "eval": [
            _row(f"ours (tuned): {bp} -> {bp}", 1.0, 1.0),
            _row(f"ours (tuned): {bp} -> {dyn}", 0.708, 0.704),
            _row(f"ours (tuned): {bp} -> {dyn} (shielded)", 0.75, 0.74),
            _row(f"ours (default, memory-escape-noise): {bp} -> {bp}", 1.0, 0.999),
            _row(f"ours (default, memory-escape-noise): {bp} -> {dyn}", 1.0, 0.976),
        ],
    }
    pages.renders_the_page(tmp_path, capsys, "speed.md", "speed-sb3", data, ("0.976", "0.981"))

"""The tables of the paper page: each renderer gives the committed page's block back from JSONs in the shape of
``make paper``'s report.json (runs summarised by its own ``summarize``), ``eval``'s results.json and ``cross``'s
cross.json holding the page's numbers, and a re-run's number lands in it."""

from dtradar_rl.experiments.paper_seeds import summarize

PAGE = "paper.md"


def renders_several(pages, tmp_path, capsys, marker: str, datas: list, change: tuple[int, str, str]) -> None:
    pages.renders_runs(tmp_path, capsys, PAGE, marker, datas, change)


def greedy(reached: bool, collisions: int = 0, closest: int = 0) -> dict:
    return {"reached": reached, "steps": 0, "collisions": collisions, "closest": closest}


def run(seed, pair, min_steps, at, env_steps=0, bp=True, dyn=None, within=None, **more) -> dict:
    """One seed's row of run_seed, the fields the page reads."""
    g = {"blueprint": bp if isinstance(bp, dict) else greedy(bp)}
    if dyn is not None:
        g["dynamic"] = dyn if isinstance(dyn, dict) else greedy(dyn)
    row = {"seed": seed, "pair": pair, "min_steps": min_steps, "min_episode": at, "first_within_10pct": within,
           "env_steps": env_steps, "greedy": g, "reached": 1 if min_steps else 0, "episodes": 80, "updates": 1,
           "wall_s": 1.0, "reused": False, "threads": 1}  # fmt: skip
    return {**row, **more}


def entry(scene: str, runs: list, paper: tuple[int, int]) -> dict:
    """A report's training entry: the runs summarised as make paper does, the paper's Table VI row beside."""
    return {**summarize(scene, runs), "paper": {"min_steps": paper[0], "episode": paper[1]}}


def indoor() -> dict:
    cub = {"start": [13, 0], "target": [38, 17], "shortest": 42}
    meet = {"start": [0, 0], "target": [36, 37], "shortest": 73}
    steps = (39_049, 45_488, 37_794, 58_147, 63_398)
    first = (87, 42, 112, 87, 90)
    cubicle = [run(s, cub, 42, at, steps[s], dyn=True, within=first[s]) for s, at in enumerate((79, 87, 79, 252, 116))]
    steps = (50_903, 68_009, 58_149, 67_274, 67_597)
    first = (67, 36, 93, 60, 80)
    meeting = [
        run(s, meet, 73, at, steps[s], bp=greedy(s != 4, 693 if s == 4 else 0), dyn=s == 2, within=first[s])
        for s, at in enumerate((159, 334, 158, 255, 180))
    ]
    return {"training": [entry("cubicle", cubicle, (45, 13)), entry("meeting", meeting, (78, 389))]}


def test_the_indoor_seeds_table_is_table_vi_judged_over_the_reports_seeds(pages, tmp_path, capsys):
    pages.renders_the_page(tmp_path, capsys, PAGE, "paper-seeds", indoor(), ("389", "391"))


def test_the_per_seed_table_holds_each_run_in_a_cell_the_blueprints_miss_in_bold(pages, tmp_path, capsys):
    pages.renders_the_page(tmp_path, capsys, PAGE, "paper-per-seed", indoor(), ("693", "695"))


def test_the_dallas_table_is_each_quadrants_first_seed(pages, tmp_path, capsys):
    rows = [  # quadrant, shortest, min steps (episode), env steps, seconds, paper
        (1, 96, (638, 80), 76_478, 402, (808, 19)),
        (2, 73, (None, None), 58_400, 336, (1475, 32)),
        (3, 90, (None, None), 72_000, 371, (416, 37)),
        (4, 43, (99, 65), 36_666, 194, (307, 25)),
    ]
    training = []
    for q, shortest, (best, at), steps, wall, paper in rows:
        r = run(0, {"start": [0, 0], "target": [1, 1], "shortest": shortest}, best, at, steps, bp=False,
                dyn=False if q == 3 else None, wall_s=wall)  # fmt: skip
        training.append(entry(f"dallas-q{q}", [r], paper))
    data = {"training": training}
    pages.renders_the_page(tmp_path, capsys, PAGE, "paper-one-seed", data, ("808", "810"))


def until_reports() -> list[dict]:
    def quadrant(q, shortest, best, at, closest, first, dyn=None, unfinished=None, episodes=None, seeds=range(5)):
        pair = {"start": [0, 0], "target": [1, 1], "shortest": shortest}
        out = []
        for i, s in enumerate(seeds):
            bp = greedy(closest[i] is None, closest=closest[i] or 0)
            d = None if dyn is None else greedy(False, closest=dyn[i])
            n = 400 if episodes is None else episodes[i]
            out.append(
                run(s, pair, best[i], at[i], bp=bp, dyn=d, episodes=n, reached=n, first_episode_steps=first[i],
                    first_episode_finished=bool(n), unfinished_steps=0 if unfinished is None else unfinished[i])
            )  # fmt: skip
        return out

    q1 = quadrant(1, 96, (100, 104, 105, 109, 113), (71, 74, 80, 72, 78), (78, 86, 10, 6, 48),
                  (6_843, 4_804, 148_326, 5_000, 9_000))  # fmt: skip
    q2 = quadrant(2, 73, (75, 77, 95, 78, 76), (63, 67, 76, 65, 70), (62, 10, 43, 4, None),
                  (14_787, 5_398, 47_395, 10_000, 20_000))  # fmt: skip
    q4 = quadrant(4, 43, (43, 45, 50, 44, 46), (29, 48, 66, 40, 50), (2, None, 6, None, 3),
                  (11_398, 1_151, 45_828, 5_000, 20_000))  # fmt: skip
    q3 = quadrant(3, 90, (118, 357, None, 803, 204), (6, 29, None, 10, 18), (89, 90, 89, 90, 90),
                  (4_568, 9_528, 600_000, 12_000, 5_000), dyn=(91, 92, 91, 92, 92),
                  unfinished=(520_282, 356_978, 600_000, 547_321, 526_611), episodes=(32, 18, 0, 7, 17))  # fmt: skip
    paper = {1: (808, 19), 2: (1475, 32), 3: (416, 37), 4: (307, 25)}
    return [
        {"training": [entry(f"dallas-q{q}", runs, paper[q]) for q, runs in ((1, q1), (2, q2), (4, q4))]},
        {"training": [entry("dallas-q3", q3[:2], paper[3])]},
        {"training": [entry("dallas-q3", q3[2:], paper[3])]},
    ]


def test_the_until_table_merges_a_quadrants_seeds_from_three_reports(pages, tmp_path, capsys):
    renders_several(pages, tmp_path, capsys, "paper-until", until_reports(), (0, "808", "810"))


def test_the_until_table_is_the_same_whatever_report_holds_which_seeds(pages):
    tables = pages.results_pages.RENDERERS["paper-until"].render
    a, b, c = until_reports()
    assert tables([a, c, b], {}) == tables([a, b, c], {})


def eval_result(q: int, rows: list[tuple], shared_s: float) -> dict:
    results = []
    for variant, success, spl, collisions, steps, shortest in rows:
        m = {"success_rate": success, "spl": spl, "collisions": collisions, "steps": steps, "shortest": shortest}
        name = f"dallas-q{q}/{variant}"
        case = f"dallas-q{q}/blueprint -> {name}"
        results += [
            {"case": case, "dataset": name, "shield": False, **m},
            {"case": case + " (shielded)", "dataset": name, "shield": True, **m, "success_rate": 0.5},
            {"case": "planner: " + case, "dataset": name, "shield": False, **m, "success_rate": 0.4},
        ]
    return {"config": {"eval": {"scene": f"dallas-q{q}"}, "train_stats": {"wall_s": shared_s}}, "results": results}


def test_the_city_navigation_table_sets_each_quadrants_eval_beside_the_idle_training_time(pages, tmp_path, capsys):
    evals = [
        eval_result(1, [("blueprint", 0.966, 0.963, 0.0, 58.3, 43.0)], 916),
        eval_result(2, [("blueprint", 0.980, 0.977, 0.0, 54.7, 45.8)], 798),
        eval_result(
            3, [("blueprint", 0.972, 0.969, 0.97, 58.8, 46.6), ("dynamic", 0.710, 0.703, 14.45, 170.2, 47.3)], 464
        ),  # fmt: skip
        eval_result(4, [("blueprint", 0.966, 0.965, 1.92, 59.0, 44.0)], 516),
    ]
    idle = {"dallas-q1": 85, "dallas-q2": 82, "dallas-q3": 86, "dallas-q4": 82}
    report = {"training": [], "cross": [{"group": "dallas", "train_s": idle}]}
    renders_several(pages, tmp_path, capsys, "paper-navigation", [*evals, report], (4, "86", "88"))


def test_the_cross_matrix_names_the_quadrants_and_bolds_the_own_one(pages, tmp_path, capsys):
    success = [[0.966, 0.050, 0.026, 0.080], [0.074, 0.980, 0.062, 0.046], [0.128, 0.034, 0.972, 0.088],
               [0.130, 0.032, 0.042, 0.966]]  # fmt: skip
    spl = [[0.963, 0.050, 0.026, 0.079], [0.071, 0.977, 0.061, 0.043], [0.125, 0.033, 0.969, 0.085],
           [0.128, 0.031, 0.041, 0.965]]  # fmt: skip
    scenes = [f"dallas-q{q}" for q in range(1, 5)]
    data = {"config": {"cross": {"scenes": scenes}, "matrix": {"rows": scenes, "cols": scenes, "success": success,
            "spl": spl}}, "results": []}  # fmt: skip
    pages.renders_the_page(tmp_path, capsys, PAGE, "paper-cross", data, ("0.128", "0.138"))

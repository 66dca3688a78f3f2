"""No two runs write one JSON: a JSON that the speed or a navigation page names and another results page names too
is one run's, listed here with that run's command (a page's own runs write paths of their own, with ``--out`` or
``--name``, so that re-running one page's command never re-renders another page's table from a different run)."""

from collections import defaultdict

#: The pages checked (their runs); another page's JSONs are checked where one of these names them.
PAGES = ("speed.md", "navigation.md", "navigation-movers.md")
#: JSON path -> the one run that writes it, for the paths that one of PAGES and another results page name.
SHARED = {
    "results/bench_rl.json": "make bench-rl (speed: its headline and evaluation; navigation: its robust and SB3 rows)",
}


def test_a_json_that_the_speed_or_a_navigation_page_shares_with_another_page_is_one_runs_listed_here(pages):
    rp = pages.results_pages
    named: dict[str, set[str]] = defaultdict(set)
    for page in sorted((pages.ROOT / "docs" / "results").glob("*.md")):
        for block in rp.blocks(page.read_text(encoding="utf-8"), page.name):
            for path in rp.paths(block):
                named[path].add(page.name)
    across = {path: sorted(where) for path, where in named.items() if len(where) > 1 and set(where) & set(PAGES)}
    assert set(across) <= set(SHARED), {p: w for p, w in across.items() if p not in SHARED}
    assert set(SHARED) <= set(across)  # a listed path no longer shared: drop it from the list


def test_the_navigation_pages_decision_times_are_not_the_speed_pages_run(pages):
    """The two pages' ``make bench-latency`` runs on the cubicle differ (the memory agent, the tuned agent)."""
    _, nav = pages.block_of("navigation.md", "navigation-latency")
    _, speed = pages.block_of("speed.md", "bench-latency")
    assert not set(pages.results_pages.paths(nav)) & set(pages.results_pages.paths(speed))

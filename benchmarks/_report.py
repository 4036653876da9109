"""Where benchmark results go: benchmarks/results/<name>.json (everything) and <name>.md (the summary)."""
import json
import os

# EVENTFIELD_RESULTS_DIR sends them elsewhere (a GPU session collects them under its $OUT: gpu_session.sh)
RESULTS = os.environ.get("EVENTFIELD_RESULTS_DIR") or os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                                   "results")
os.makedirs(RESULTS, exist_ok=True)


def write_results(name: str, results: dict, markdown_lines: list) -> None:
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, f"{name}.json"), "w") as f:
        json.dump(results, f, indent=2)
    with open(os.path.join(RESULTS, f"{name}.md"), "w") as f:
        f.write("\n".join(markdown_lines))
    print("\n".join(markdown_lines))
    print(json.dumps(results.get("targets", {}), indent=2))


def profile_rows(stats, key: str, count: int) -> list:
    """The first ``count`` functions of a ``pstats.Stats`` sorted by ``key`` ("tottime", "cumulative"), as dicts:
    function (path from the project root where it is in it, else the file name; line; name), calls, own and
    cumulative ms. The one reading of cProfile's table for the profiling benchmarks."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    stats.sort_stats(key)
    rows = []
    for func in stats.fcn_list[:count]:
        calls, _, own, cumulative, _ = stats.stats[func]
        path, line, name = func
        where = os.path.relpath(path, root) if path.startswith(root) else os.path.basename(path)
        rows.append({"function": f"{where}:{line} {name}", "calls": calls, "own_ms": 1e3 * own,
                     "cumulative_ms": 1e3 * cumulative})
    return rows

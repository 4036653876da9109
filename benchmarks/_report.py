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

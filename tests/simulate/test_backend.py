import pytest

import mitsuba_eventfield as ef


def test_auto_choice_is_vectorised_mono_or_rgb():
    assert ef.choose_variant() in ("llvm_ad_mono", "cuda_ad_mono")
    assert ef.choose_variant(color=True).endswith("_ad_rgb")
    assert ef.choose_variant("llvm") == "llvm_ad_mono"


@pytest.mark.parametrize("variant, message", [("scalar_rgb", "90x slower"), ("llvm_ad_foo", "not compiled")])
def test_bad_variants_are_refused(variant, message):
    with pytest.raises(ef.EventFieldError, match=message):
        ef.choose_variant(variant)


def test_the_environment_names_the_variant_of_any_command(monkeypatch, tmp_path, capsys):
    """EVENTFIELD_VARIANT reaches commands without --variant (the demo, the applications): a name this Mitsuba
    lacks is refused by the demo, in one line naming the variable, before anything is rendered."""
    from mitsuba_eventfield.cli.main import main as cli
    monkeypatch.setenv("EVENTFIELD_VARIANT", "llvm_ad_rgb")
    assert ef.choose_variant() == "llvm_ad_mono"                 # the backend it names; mono / rgb as asked
    assert ef.choose_variant(color=True) == "llvm_ad_rgb"       # (a full name made colour probes mono)
    monkeypatch.setenv("EVENTFIELD_VARIANT", "llvm")
    assert ef.choose_variant(color=True) == "llvm_ad_rgb"
    assert ef.choose_variant("llvm_ad_mono", color=True) == "llvm_ad_mono"      # an explicit choice wins
    monkeypatch.setenv("EVENTFIELD_VARIANT", "llvm_ad_foo")
    with pytest.raises(ef.EventFieldError, match="EVENTFIELD_VARIANT=llvm_ad_foo: variant 'llvm_ad_foo' is not "
                                                 "compiled"):
        ef.choose_variant()
    monkeypatch.setattr("mitsuba_eventfield.backend._active", None)      # as in a fresh process
    assert cli(["demo", "-o", str(tmp_path / "demo")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("eventfield: error: EVENTFIELD_VARIANT=llvm_ad_foo") and "\n" not in err
    assert not (tmp_path / "demo").exists()


def test_llvm_library_is_at_least_16():
    import os
    import re
    path = os.environ.get("DRJIT_LIBLLVM_PATH", "")
    m = re.search(r"LLVM[-.]?(\d+)", os.path.basename(path))
    assert m and int(m.group(1)) >= 16, path


APPENDERS = """
import json, sys
import mitsuba as mi
mi.set_variant(sys.argv[2])
def appenders():
    log = mi.logger()
    return [type(log.appender(i)).__name__ for i in range(log.appender_count())]
seen = {"before": appenders()}
import mitsuba_eventfield as ef
seen["import"] = appenders()
ef.set_variant(sys.argv[2])
ef.load_scene(ef.scene.bundled_scene("demo/demo.xml"), width=8, height=6)
seen["set_variant"] = appenders()
ef.quiet_mitsuba_log()
ef.quiet_mitsuba_log()                              # idempotent
seen["quiet"] = appenders()
ef.quiet_mitsuba_log(False)
seen["restored"] = appenders()
from mitsuba_eventfield import cli
cli.main(["info", sys.argv[1]])
seen["after_cli"] = appenders()
print(json.dumps(seen))
"""


def test_mitsuba_log_is_ours_only_when_asked(tmp_path):
    """Importing the package or choosing a variant leaves Mitsuba's appenders as they were (a fresh process, so
    no other test's state counts); quiet_mitsuba_log() replaces them, (False) puts them back, and so does the
    CLI once it returns."""
    import json
    import subprocess
    import sys
    path = str(tmp_path / "e.h5")
    ef.write_events(path, ef.EventStream([1], [2], [3], [1], 8, 6, {}))
    from conftest import TEST_VARIANT
    r = subprocess.run([sys.executable, "-c", APPENDERS, path, TEST_VARIANT], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    seen = json.loads(r.stdout.strip().splitlines()[-1])
    assert seen["before"] == ["StreamAppender"]
    for when in ("import", "set_variant", "restored", "after_cli"):
        assert seen[when] == seen["before"], (when, seen)
    assert seen["quiet"] == ["_FilteringAppender"]
    assert "Monochrome mode enabled" in r.stdout       # Mitsuba's own appender (it writes to stdout) still speaks


def test_cli_prints_only_our_lines(tmp_path, capfd):
    """With the quiet log the CLI shows no Mitsuba notes (here: the monochrome film note on every mono load),
    then leaves the log as it found it."""
    import mitsuba as mi
    from conftest import DEMO

    from mitsuba_eventfield import cli
    log = mi.logger()
    before = [log.appender(i) for i in range(log.appender_count())]
    capfd.readouterr()
    out = str(tmp_path / "f.exr")
    assert cli.main(["frame", DEMO, "-o", out, "-D", "width=16", "-D", "height=12", "--times", "0"]) == 0
    out, err = capfd.readouterr()
    assert "WARN" not in out + err and "Monochrome" not in out + err, out + err   # Mitsuba's appender: stdout
    assert [log.appender(i) for i in range(log.appender_count())] == before

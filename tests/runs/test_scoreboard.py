"""bench/: the scoreboard's blocks and its rewrite, what bench/ may hold, and the one-line
errors of the maintained benchmarks' arguments (no device: nothing here renders)."""
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BENCH = REPO / "bench"
sys.path.insert(0, str(BENCH))

import harness  # noqa: E402
import scoreboard  # noqa: E402


def test_every_block_has_its_markers_in_results_once():
    text = (BENCH / "RESULTS.md").read_text()
    for block in scoreboard.BLOCKS:
        assert text.count(f"<!-- results:{block.name} -->") == 1, block.name
        assert text.count(f"<!-- /results:{block.name} -->") == 1, block.name
        assert scoreboard.marker(block.name).search(text), block.name


def test_every_block_names_its_command_in_results():
    """Each table says how to make it again: the block's own command heads it."""
    text = (BENCH / "RESULTS.md").read_text()
    for block in scoreboard.BLOCKS:
        body = scoreboard.marker(block.name).search(text).group(2)
        command = scoreboard.command_line(block.full, None).split(" ", 1)[1]  # without .venv/bin/…
        assert command in body, block.name


def test_a_block_is_rewritten_and_the_prose_around_it_stays():
    text = "intro\n<!-- results:stages -->\nold table\n<!-- /results:stages -->\noutro\n"
    rewritten = scoreboard.marker("stages").sub(lambda m: m.group(1) + "new table\n" + m.group(3), text)
    assert rewritten == "intro\n<!-- results:stages -->\nnew table\n<!-- /results:stages -->\noutro\n"


def test_the_scoreboard_stays_a_scoreboard():
    """bench/RESULTS.md holds today's figures, bench/ the maintained benchmarks: at most ~400
    lines, 15 scripts and 1 MB of committed outputs."""
    assert len((BENCH / "RESULTS.md").read_text().splitlines()) <= 400
    assert len(list(BENCH.glob("*.py"))) <= 15
    tracked = subprocess.run(["git", "-C", str(REPO), "ls-files", "bench"], capture_output=True, text=True)
    if tracked.returncode != 0 or not tracked.stdout.strip():
        pytest.skip("not a git checkout")
    sizes = [(REPO / name).stat().st_size for name in tracked.stdout.split() if (REPO / name).is_file()]
    assert sum(sizes) <= 1 << 20


def test_every_command_the_scoreboard_runs_is_in_bench():
    for block in scoreboard.BLOCKS:
        for words in (block.full, block.quick):
            assert words[0] == "clrays" or (REPO / words[0]).is_file(), words


def test_list_prints_each_block_without_running_it():
    done = subprocess.run([sys.executable, str(BENCH / "scoreboard.py"), "--list", "--device", "intel"],
                          capture_output=True, text=True, cwd=REPO)
    assert done.returncode == 0
    assert [line.split(":")[0] for line in done.stdout.splitlines()] == [b.name for b in scoreboard.BLOCKS]
    assert "stages: CLRAYS_DEVICE=intel .venv/bin/python bench/stage_times.py --size 1280x720" in done.stdout


@pytest.mark.parametrize("arguments, message", [
    (["scoreboard.py", "--only", "speeds"], "--only: no block 'speeds'; the blocks are"),
    (["ab.py", "stages", "--repo", "no-such-ref"], "ab.py: 'no-such-ref': neither a folder nor a git ref"),
    (["ab.py", "stages", "--size", "1280by720"], "argument --size: expected WxH, e.g. 1280x720, got '1280by720'"),
    (["ab.py", "kernels", "gather", "--env", "POCL"], "--env: expected NAME=VALUE, got 'POCL'"),
    (["ab.py", "stages", "nowhere"], "ab.py: scenes: no scenes/nowhere.yaml"),
    (["stage_times.py", "--frames", "0"], "argument --frames: expected a positive integer, got '0'"),
    (["errors.py", "orbit@ten", "--size", "16x9"], "errors.py: scenes: expected NAME or NAME@FRAME, got 'orbit@ten'"),
])
def test_bad_arguments_are_one_line(arguments, message):
    done = subprocess.run([sys.executable, str(BENCH / arguments[0]), *arguments[1:]], capture_output=True,
                          text=True, cwd=REPO)
    assert done.returncode != 0
    assert message in done.stderr
    assert "Traceback" not in done.stderr


def test_image_sizes_and_counts_are_checked():
    assert harness.image_sizes("96x64,1280x720") == ["96x64", "1280x720"]
    assert harness.width_height("1280x720") == (1280, 720)
    with pytest.raises(Exception, match="expected WxH"):
        harness.image_sizes("96x64,12x")
    with pytest.raises(Exception, match="positive integer"):
        harness.frame_count("-1")


def test_in_turns_runs_every_side_once_a_round():
    calls = []
    results = harness.in_turns(3, ["A", "B"], lambda side: calls.append(side) or len(calls))
    assert calls == ["A", "B"] * 3
    assert results == [[1, 3, 5], [2, 4, 6]]


def test_markdown_table_aligns_the_columns_asked():
    table = harness.markdown_table(["scene", "ms"], [["demo", "1.0"]], right=[1])
    assert table.splitlines() == ["| scene | ms |", "|---|---:|", "| demo | 1.0 |"]

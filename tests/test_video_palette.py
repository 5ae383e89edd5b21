"""``rehabbot render --gif-colors N`` (``render_episode(..., gif_colors=N)``): a GIF whose
frames share one palette of at most N colours, checked like every video (frames and
durations read back); a bad N, or N for an .mp4, is refused before the episode."""

from __future__ import annotations

import json

import pytest

from rehabbot.cli import main

ENV = "rehab-reach-v0"
SHORT = ["--env", ENV, "--width", "64", "--height", "48", "--frame-every", "5",
         "--env-kwargs", json.dumps({"max_episode_steps": 40})]


def _colours(path) -> set:
    """Every RGB colour that any frame of the GIF shows."""
    from PIL import Image

    colours = set()
    with Image.open(path) as image:
        for index in range(image.n_frames):
            image.seek(index)
            colours.update(colour for _count, colour in image.convert("RGB").getcolors(1 << 16))
    return colours


@pytest.mark.slow
def test_a_gif_with_one_palette_of_n_colours(tmp_path, capsys) -> None:
    pytest.importorskip("imageio")
    shared, own = tmp_path / "shared.gif", tmp_path / "own.gif"
    assert main(["render", "expert", "--out", str(shared), "--gif-colors", "8", *SHORT]) == 0
    assert "9 frames" in capsys.readouterr().out  # reset + 40 steps / 5
    assert 2 <= len(_colours(shared)) <= 8  # every frame's colours come from one palette
    assert main(["render", "expert", "--out", str(own), *SHORT]) == 0
    assert len(_colours(own)) > 8  # the default: a palette of its own for each frame


@pytest.mark.parametrize(("args", "words"), [
    (["--gif-colors", "1"], "--gif-colors: must be an integer in [2, 256], got '1'"),
    (["--gif-colors", "257"], "--gif-colors: must be an integer in [2, 256], got '257'"),
])
def test_a_bad_number_of_colours_is_refused(tmp_path, capsys, args, words) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["render", "expert", "--out", str(tmp_path / "x.gif"), *args, *SHORT])
    assert stop.value.code == 2 and words in capsys.readouterr().err


def test_gif_colors_for_an_mp4_is_refused(tmp_path, capsys) -> None:
    assert main(["render", "expert", "--out", str(tmp_path / "x.mp4"), "--gif-colors", "64",
                 *SHORT]) == 2
    assert "--gif-colors applies to a .gif" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []

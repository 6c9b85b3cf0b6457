"""Markdown and plots of a closure result (files only where the caller says)."""

from __future__ import annotations

from accal.closure import close_loop
from accal.closure.report import plot_closure, to_markdown, write_json


def test_markdown_json_and_plots(sim, tmp_path):
    d = sim(3, step=(0.4, 2e-9), n=43200, dt=2.0)
    res = close_loop(d["t"], d["y"], candidates=("bias_step",))
    md = to_markdown(res, truth=d["truth"])
    assert "bias_step" in md and "true error" in md
    assert write_json(res, tmp_path / "closure.json").stat().st_size > 0
    a, b = plot_closure(res, tmp_path / "res.png", tmp_path / "psd.png")
    assert a.stat().st_size > 0 and b.stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["closure.json", "psd.png", "res.png"]

"""The Painter Street study's final-model table: what the diagnosis ends with, against SRIM."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))

from real_final import final_error, final_lines, final_rows  # noqa: E402


def _diag(event, direction, verdict, nominal, extended, role="untouched"):
    return {
        "event": event,
        "direction": direction,
        "role": role,
        "status": "ok",
        "verdict": verdict,
        "causes": [],
        "learned": verdict == "unexplained",
        "gain": {"metric": "heldout_nrmse_a", "nominal": nominal, "extended": extended},
        "wall_s": 100.0,
    }


def _ident(event, direction, held, srim, role="untouched"):
    return {
        "event": event,
        "direction": direction,
        "role": role,
        "status": "ok",
        "pga_g": 0.05,
        "heldout_nrmse_a": held,
        "srim_heldout_nrmse_a": srim,
    }


def test_the_final_model_is_the_kept_extension_or_the_nominal():
    assert final_error(_diag("a", "transverse", "unexplained", 0.6, 0.4)) == 0.4
    assert final_error(_diag("a", "transverse", "none", 0.6, None)) == 0.6
    # a learned force that was not kept leaves no extended error: the nominal model is final
    assert final_error(_diag("a", "transverse", "unexplained", 0.6, None)) == 0.6


def test_the_table_pairs_each_diagnosis_with_its_own_direction_and_counts_against_srim():
    ident = [
        _ident("a", "transverse", 0.62, 0.52),
        _ident("a", "longitudinal", 0.30, 0.90),
        _ident("b", "transverse", 0.50, None),
    ]
    diag = [
        _diag("a", "transverse", "unexplained", 0.62, 0.39),
        _diag("a", "longitudinal", "none", 0.31, None),
        _diag("b", "transverse", "none", 0.5, None),
    ]
    rows = {(r["event"], r["direction"]): r for r in final_rows(ident, diag)}
    assert rows[("a", "transverse")]["final"] == 0.39 and rows[("a", "transverse")]["srim"] == 0.52
    assert rows[("a", "longitudinal")]["final"] == 0.31
    text = "\n".join(final_lines(ident, diag, lambda r: ""))
    assert text.count("3 of the 3 identified events and directions") == 1
    assert (
        "transverse, events kept out of all tuning (1 with a stable SRIM model): at or below SRIM's held-out "
        in text
    )
    assert "the final model on 1, the diagnosis' nominal model on 0, the identification on 0" in text
    assert "| b | transverse | 0.050 | none | 0.500 / 0.500 / 0.500 / - | - |" in text


def test_a_sweep_not_run_again_keeps_its_published_section(tmp_path, monkeypatch):
    import real

    (tmp_path / "README.md").write_text(
        "# t\n\n## Two modes against one\n\n| a |\n|---|\n| 1 |\n\n## Diagnosis of the strong events\n\nx\n"
    )
    monkeypatch.setattr(real, "RESULTS", tmp_path)
    kept = real.kept_section("## Two modes against one", "## Diagnosis", "two_modes")
    assert kept[0] == "## Two modes against one" and "| 1 |" in kept
    assert "`two_modes`" in kept[2] and not any(line.startswith("## Diagnosis") for line in kept)
    (tmp_path / "README.md").write_text("\n".join(["# t", "", *kept, "## Diagnosis of x"]))
    again = real.kept_section("## Two modes against one", "## Diagnosis", "two_modes")
    assert sum("Kept from an earlier study" in line for line in again) == 1  # said once, not stacked
    assert real.kept_section("## Absent", "## Diagnosis", "x") == []


def test_a_direction_weak_in_a_strong_event_is_judged_apart():
    import real

    def row(direction, pga, period, ci):
        return {
            "event": "e",
            "direction": direction,
            "status": "ok",
            "pga_g": pga,
            "period_s": period,
            "period_ci95": ci,
            "srim_period_s": 0.25,
            "okid_era_period_s": 0.23,
        }

    rows = real.with_event_pga(
        [row("transverse", 0.14, 0.27, [0.25, 0.28]), row("longitudinal", 0.07, 0.21, [0.20, 0.22])]
    )
    assert [r["event_pga_g"] for r in rows] == [0.14, 0.14]
    assert real.judge(rows[0]) == {}  # strong in its own direction: no span test
    assert real.judge(rows[1]) == {"inside_peers": False, "weak_event": False}
    alone = real.with_event_pga([row("longitudinal", 0.07, 0.24, [0.22, 0.26])])
    assert real.judge(alone[0]) == {"inside_peers": True, "weak_event": True}


def test_the_profile_interval_is_judged_beside_the_wald_one():
    """A weak event's profile set is tested against the peers' span too, an open end as unbounded,
    and shown in the identification table."""
    import real

    row = {
        "event": "e",
        "direction": "longitudinal",
        "role": "untouched",
        "date": "2020-01-01",
        "status": "ok",
        "pga_g": 0.02,
        "event_pga_g": 0.02,
        "period_s": 0.16,
        "period_ci95": [0.15, 0.17],
        "damping": 0.2,
        "damping_ci95": [0.1, 0.3],
        "heldout_nrmse_a": 0.2,
        "wall_s": 10.0,
        "inputs": [1],
        "outputs": [2],
        "srim_period_s": 0.27,
        "okid_era_period_s": 0.25,
    }
    assert real.judge({**row, "period_profile_ci95": [0.14, 0.2]}) == {
        "inside_peers": False,
        "weak_event": True,
        "profile_inside_peers": False,
    }
    assert real.judge({**row, "period_profile_ci95": [0.14, None]})["profile_inside_peers"]
    assert "profile_inside_peers" not in real.judge(row)
    table = "\n".join(
        real.identification_table([{**row, "period_profile_ci95": [0.14, None]}], "longitudinal")
    )
    assert "| [0.140, ...] (in) |" in table and "0.160 [0.150, 0.170] (**out**)" in table

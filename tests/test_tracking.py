from workflow.common import tracking


def test_two_runs_logged_and_compared(tmp_path, capsys):
    uri = f"sqlite:///{tmp_path / 'ledger.db'}"
    art = tmp_path / "a.txt"
    art.write_text("x")
    ids = [
        tracking.log_run(
            uri=uri,
            experiment="t",
            patient=p,
            params={"patient": {"coded": {"depth": d}}},
            metrics={"active_limit_MCP_nm": m},
            artifacts=[art],
            config_slice={"d": d},
        )
        for p, d, m in [("a", 0.0, 5.0), ("b", 0.5, 6.0)]
    ]
    df = tracking.compare_runs(uri, *ids)
    assert df.loc["metric.active_limit_MCP_nm"].tolist()[:2] == [5.0, 6.0]
    assert bool(df.loc["param.patient.coded.depth", "differs"])
    assert not bool(df.loc["tag.git_commit", "differs"])
    assert tracking.main(["--uri", uri, "compare", *ids]) == 0
    assert "active_limit_MCP_nm" in capsys.readouterr().out


def test_rule_times_reads_benchmark_files(tmp_path):
    (tmp_path / "rsm.tsv").write_text("s\th:m:s\tmax_rss\n1.25\t0:00:01\t100\n")
    assert tracking.rule_times(tmp_path) == {"time_rsm_s": 1.25}


def test_flatten():
    assert tracking.flatten({"a": {"b": 1, "c": {"d": 2}}}) == {"a.b": 1, "a.c.d": 2}

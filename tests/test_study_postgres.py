"""Several server processes on one real PostgreSQL database (a throwaway cluster from
Debian's `postgresql` package, started with initdb/pg_ctl in a temporary folder)."""

import threading

import pytest
import sqlalchemy as sa
from study_fixtures import ADMIN, ANS, TOKEN, answer, make_client, register

from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.pg_local import LocalPostgres, find_pg_bin

pytestmark = [pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")]


@pytest.fixture(scope="module")
def pg():
    if find_pg_bin() is None:
        pytest.skip("PostgreSQL server binaries not installed (Debian package `postgresql`; scripts/setup.sh)")
    pytest.importorskip("psycopg", reason="psycopg missing (the web extra installs it)")
    with LocalPostgres() as cluster:
        yield cluster


@pytest.fixture(scope="module")
def stim_dir(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("stim"), n_files=3, seconds=1.0)


def test_two_processes_share_state_only_through_postgres(pg, stim_dir):
    # two "processes" starting together create the schema once (advisory lock), agree on the secret
    out = {}

    def start(name):
        out[name] = make_client(stim_dir, pg.url)

    threads = [threading.Thread(target=start, args=(n,)) for n in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    (a, cfg_a), (b, cfg_b) = out["a"], out["b"]
    try:
        assert cfg_a.store.blinding_secret() == cfg_b.store.blinding_secret()
        h, state = register(a, "PG_one")
        assert b.get("/api/participants/PG_one", headers=h).json()["trials"] == state["trials"]  # same tokens, URLs
        assert answer(b, "PG_one", h, state["trials"][0]).status_code == 201
        assert answer(a, "PG_one", h, state["trials"][0]).status_code == 200  # a resend elsewhere
        # the same id registered on both at once: exactly one wins
        codes = []

        def reg(client):
            codes.append(client.post("/api/participants", json={"participant_id": "PG_race"}).status_code)

        ts = [threading.Thread(target=reg, args=(c,)) for c in (a, b, a, b)]
        for t in ts:
            t.start()
        for t in ts:
            t.join()
        assert sorted(codes) == [201, 409, 409, 409]
        # the same answer sent to both processes at once: one row
        h2, st2 = register(a, "PG_dup")
        codes = []

        def send(client):
            codes.append(answer(client, "PG_dup", h2, st2["trials"][0]).status_code)

        ts = [threading.Thread(target=send, args=(c,)) for c in (a, b) * 4]
        for t in ts:
            t.start()
        for t in ts:
            t.join()
        assert sorted(codes) == [200] * 7 + [201]
        r = cfg_a.store.responses
        with cfg_a.store.engine.connect() as conn:
            assert (
                conn.execute(
                    sa.select(sa.func.count())
                    .select_from(r)
                    .where(r.c.participant_id == "PG_dup", r.c.practice.is_(False))
                ).scalar_one()
                == 1
            )
        # a secret revoked on A is refused on B at once; a withdrawal on B is seen on A
        link = a.post("/admin/participants/PG_one/resume-link", headers=ADMIN).json()["url"]
        assert b.get("/api/participants/PG_one", headers=h).status_code == 403
        new = {"X-Participant-Secret": link.split("resume=")[1]}
        assert answer(b, "PG_one", new, state["trials"][1]).status_code == 201
        assert b.post("/admin/participants/PG_one/withdraw", headers=ADMIN).status_code == 200
        assert a.get("/api/participants/PG_one", headers=new).status_code == 410
    finally:
        cfg_a.store.close()
        cfg_b.store.close()


def test_server_processes_and_bots_on_postgres(pg, stim_dir, tmp_path):
    """`crowdstudy serve --workers 2` and a second server on another port, one database:
    bots on both, every answer stored exactly once, the export whole."""
    import httpx

    from crowdstudy.study.bots import run_simulation
    from crowdstudy.study.export import export_study
    from crowdstudy.study.local_server import LocalServer

    media = tmp_path / "media"
    common = ["--stimuli", str(stim_dir), "--db", pg.url, "--media-dir", str(media)]
    with (
        LocalServer(common + ["--workers", "2"], admin_token=TOKEN) as s1,
        LocalServer(common, admin_token=TOKEN) as s2,
    ):
        r1 = run_simulation(s1.url, 4, admin_token=TOKEN, concurrency=4, seed=3, prefix="w1")
        r2 = run_simulation(s2.url, 4, admin_token=TOKEN, concurrency=4, seed=3, prefix="w2")
        assert r1.errors == [] and r2.errors == [] and r1.answers == r2.answers == 240
        # one participant across both servers, alternating
        reg = httpx.post(s1.url + "/api/participants", json={"participant_id": "PG_alt"}).json()
        h = {"X-Participant-Secret": reg["secret"]}
        base = "/api/participants/PG_alt"
        httpx.post(s2.url + base + "/consent", json={"consent": True}, headers=h).raise_for_status()
        httpx.post(s1.url + base + "/demographics", json={"age": 20, "gender": "other"}, headers=h).raise_for_status()
        httpx.post(s2.url + base + "/practice", json={"answers": ANS, "rt_ms": 9}, headers=h).raise_for_status()
        sched = httpx.get(s1.url + "/admin/participants/PG_alt/schedule", headers=ADMIN).json()["trials"]
        for t in reg["state"]["trials"][:10]:
            body = {"trial_index": t["trial_index"], "token": t["token"], "answers": ANS, "rt_ms": 1000.0}
            if t.get("check"):
                body["check"] = sched[t["trial_index"]]["check_value"]
            url = (s1 if t["trial_index"] % 2 else s2).url
            assert httpx.post(url + base + "/responses", json=body, headers=h).status_code == 201
        # videos: published once under opaque names; both servers point the browser at the same ones
        v1 = httpx.get(s1.url + base, headers=h).json()["trials"][0]["video_url"]
        v2 = httpx.get(s2.url + base, headers=h).json()["trials"][0]["video_url"]
        assert v1 == v2 and (media / v1.rsplit("/", 1)[1]).is_file()
    out = tmp_path / "responses.csv"
    export_study(pg.url, out)
    import pandas as pd

    df = pd.read_csv(out)
    df = df[~df["participant_id"].isin(["PG_dup"])]  # left by the test above (same database)
    assert not df.duplicated(["participant_id", "trial_index"]).any()
    assert df.groupby("participant_id").size().to_dict() == {
        **{f"w1-3-{i:05d}": 60 for i in range(4)},
        **{f"w2-3-{i:05d}": 60 for i in range(4)},
        "PG_alt": 10,
    }

"""Blinding against a participant who has the source code: each leak of issue 15 tried."""

import json
import os

import pytest
from study_fixtures import ADMIN, make_client, register

from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.media import MEDIA_NAME_PATTERN, PUBLISHED_MTIME
from crowdstudy.study.schedule import make_schedule

pytestmark = [pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")]


@pytest.fixture(scope="module")
def stim_dir(tmp_path_factory):
    stim = write_fake_stimuli(tmp_path_factory.mktemp("stim"), n_files=3, seconds=1.0)
    # the files were "rendered" in design order: mtimes increasing along the manifest
    manifest = json.loads((stim / "manifest.json").read_text())
    seen = {}
    for k, row in enumerate(manifest["stimuli"]):
        seen.setdefault(row["file"], 1_700_000_000 + 60 * k)
    for rel, t in seen.items():
        os.utime(stim / rel, (t, t))
    return stim


@pytest.fixture
def api(stim_dir, tmp_path):
    client, cfg = make_client(stim_dir, f"sqlite:///{tmp_path / 'b.db'}")
    yield client
    cfg.store.close()


def test_schedule_cannot_be_recomputed_from_the_public_seed(api):
    """(a) the public seed and the participant's id no longer give the server's order."""
    design = api.app.state.config.design
    by_stage = api.app.state.study.by_stage
    for pid in ("P_a1", "P_a2", "P_a3"):
        _, state = register(api, pid, ready=False)
        served = [
            t["stimulus_id"] for t in api.get(f"/admin/participants/{pid}/schedule", headers=ADMIN).json()["trials"]
        ]
        public = [t.stimulus_id for t in make_schedule(by_stage, pid, design.seed)]
        assert sorted(served) == sorted(public) and served != public
        # the order is keyed with the secret kept in the database (nothing the browser has)
        keyed = [
            t.stimulus_id
            for t in make_schedule(by_stage, pid, design.seed, secret=api.app.state.config.store.blinding_secret())
        ]
        assert served == keyed
        assert api.app.state.config.store.blinding_secret() not in json.dumps(state)


def test_videos_carry_no_order_revealing_header(api):
    """(b) no Last-Modified / ETag; all video responses have the same headers but the size."""
    _, state = register(api, "P_b", ready=False)
    urls = [t["video_url"] for t in state["trials"]] + [state["practice"]["video_url"]]
    assert all(MEDIA_NAME_PATTERN.fullmatch(u.rsplit("/", 1)[1]) for u in urls)
    seen = []
    for u in urls:
        for r in (api.get(u), api.head(u), api.get(u, headers={"Range": "bytes=0-9"})):
            assert r.status_code in (200, 206)
            names = {k.lower() for k in r.headers}
            assert "last-modified" not in names and "etag" not in names, dict(r.headers)
            seen.append(
                (
                    r.status_code,
                    {
                        k: v
                        for k, v in r.headers.items()
                        if k.lower() not in ("content-length", "content-range", "date")
                    },
                )
            )
    by_status = {}
    for status, headers in seen:
        by_status.setdefault(status, []).append(headers)
    for group in by_status.values():
        assert all(h == group[0] for h in group), group[:2]


def test_published_media_are_opaque_and_all_dated_alike(stim_dir, tmp_path):
    """(b) for nginx / a CDN: copies under opaque names, one mtime for all; two server
    processes on one database publish the same names; the browser gets the media URL."""
    db = f"sqlite:///{tmp_path / 'm.db'}"
    out = tmp_path / "media"
    a, cfg_a = make_client(stim_dir, db, media_dir=out, media_url="https://cdn.example.org/study")
    files = sorted(out.iterdir())
    assert len(files) == 61  # 60 stimuli + the practice clip
    assert all(MEDIA_NAME_PATTERN.fullmatch(f.name) for f in files)
    assert {int(f.stat().st_mtime) for f in files} == {PUBLISHED_MTIME}
    before = {f.name: f.stat().st_ino for f in files}
    b, cfg_b = make_client(stim_dir, db, media_dir=out, media_url="https://cdn.example.org/study")
    assert {f.name: f.stat().st_ino for f in out.iterdir()} == before  # idempotent: nothing rewritten
    _, state = register(a, "P_pub", ready=False)
    names = {t["video_url"].rsplit("/", 1)[1] for t in state["trials"]}
    assert all(t["video_url"].startswith("https://cdn.example.org/study/") for t in state["trials"])
    assert names <= set(before)
    # the page may load videos from that origin (CSP), and nothing else foreign
    csp = a.get("/").headers["content-security-policy"]
    assert "media-src 'self' blob: https://cdn.example.org" in csp
    # every copy has one size (no condition in Content-Length): the stimulus's bytes, then a
    # trailing MP4 "free" box that players skip
    assert len({f.stat().st_size for f in files}) == 1
    sched = a.get("/admin/participants/P_pub/schedule", headers=ADMIN).json()["trials"]
    for t in sched[:3]:
        src = cfg_a.stimuli.files[t["stimulus_id"]].read_bytes()
        pub = (out / t["video_url"].rsplit("/", 1)[1]).read_bytes()
        assert pub[: len(src)] == src
        box = pub[len(src) :]
        assert int.from_bytes(box[:4], "big") == len(box) >= 8 and box[4:8] == b"free" and not any(box[8:])
    # and the server's own /media route (a proxy may forward to it) answers with those copies
    lengths = {a.get("/media/" + t["video_url"].rsplit("/", 1)[1]).headers["content-length"] for t in sched}
    assert lengths == {str(files[0].stat().st_size)}
    # another deployment (a new database, a new secret): other names
    c, cfg_c = make_client(stim_dir, f"sqlite:///{tmp_path / 'other.db'}")
    _, other = register(c, "P_pub", ready=False)
    assert not {t["video_url"].rsplit("/", 1)[1] for t in other["trials"]} & names
    for cfg in (cfg_a, cfg_b, cfg_c):
        cfg.store.close()


def test_browser_receives_no_scoring_metadata(api):
    """(c) which items are reversed and how they pair into composites stays on the server."""
    design = api.app.state.config.design
    h, state = register(api, "P_c")
    texts = [
        api.get("/api/study").text,
        json.dumps(state),
        api.get("/api/participants/P_c", headers=h).text,
        api.get("/").text,
    ]
    for text in texts:
        assert "reverse" not in text.lower() and "composite" not in text.lower()
        for name in design.composites:
            assert name not in text
    info = api.get("/api/study").json()
    assert all(set(it) == {"id", "text"} for it in info["items"])
    # the admin (and the simulated participants) still get it
    scoring = api.get("/admin/study.json", headers=ADMIN).json()
    assert [it["reverse"] for it in scoring["items"]] == [it.reverse for it in design.items]
    assert scoring["composites"] == {k: list(v) for k, v in design.composites.items()}
    assert api.get("/admin/study.json").status_code == 401

"""Participant sessions: the browser questionnaire's server, its durable storage and export.

Running a study
---------------
::

    crowdstudy serve --stimuli stimuli/videos --db sqlite:///study.db \\
        --completion-code C1A2B3 --redirect-url "https://app.prolific.com/submissions/complete?cc=C1A2B3"

prints the participant URL (``/?PROLIFIC_PID=...&STUDY_ID=...&SESSION_ID=...`` or
``/?participant=...``; without an id the page asks for one) and the admin token (set
``CROWDSTUDY_ADMIN_TOKEN`` to keep it fixed and out of the process list). ``/admin`` shows
progress after a login with that token (a cookie; scripts send ``Authorization: Bearer``);
``crowdstudy export --db sqlite:///study.db --out responses.csv --demographics demographics.csv``
writes the analysis input (``comparisons.csv`` too for 2afc stages) and
``participants.csv`` (status, exclusion flags);
``crowdstudy participants list|withdraw|audit`` manages participants. The server binds
127.0.0.1; for an online study run it behind an HTTPS reverse proxy. ``--workers N`` runs N
processes; several servers may share one PostgreSQL database (``--db postgresql+psycopg://...``),
and ``--media-dir/--media-url`` hand the videos to nginx or a CDN.
``crowdstudy simulate-participants --url ... --admin-token ... -n 10`` runs bots through the
same API (demo, load test, checking the analysis end to end).

Blinding
--------
Participants never learn a clip's condition: stimulus ids such as ``S1-D3-V2-Ours`` (density,
viewpoint, method) appear in nothing the browser receives. The participant API names each
trial by its index, its stage and an opaque per-participant token, an HMAC of (the study's
random secret stored in the database, participant id, stimulus id)
(:mod:`crowdstudy.study.blinding`); videos have opaque per-deployment names and no file
dates (:mod:`crowdstudy.study.media`); the trial order is shuffled with the same secret
(:mod:`crowdstudy.study.schedule`), and the scoring metadata (reversed items, composites) is
admin-only. An answer carries ``trial_index`` and ``token``; the server checks the token
against that participant's schedule and stores the real stimulus id, so ``responses.csv``
keeps its schema. A 2afc trial is one token for its two videos. Each stage shows the trial of its task
(likert, slider or 2afc: :mod:`crowdstudy.study.session`). The token -> stimulus mapping is admin-only
(``GET /admin/participants/<id>/schedule``, what the simulated participants answer from, and
the exports).

Modules (import them directly; heavy dependencies load only there):

- :mod:`crowdstudy.study.schedule`: per-participant randomised trial order.
- :mod:`crowdstudy.study.blinding`: the opaque per-participant trial tokens.
- :mod:`crowdstudy.study.stimulus_set`: the stimulus manifest the server reads.
- :mod:`crowdstudy.study.storage`: SQLAlchemy Core tables (SQLite with WAL and group commit, PostgreSQL).
- :mod:`crowdstudy.study.group_commit`: SQLite's one writer thread, one fsync per batch of writes.
- :mod:`crowdstudy.study.app`: the Starlette ASGI application (``create_app``) from the route tables.
- :mod:`crowdstudy.study.routes_participant`: the participants' JSON API (``/api``).
- :mod:`crowdstudy.study.routes_static`: the page, its scripts, jsPsych and the videos.
- :mod:`crowdstudy.study.routes_admin`: the admin's dashboard, exports and actions (``/admin``).
- :mod:`crowdstudy.study.session`: the participant API's logic (no per-process state).
- :mod:`crowdstudy.study.bodies`: the checks of every value a request sends (one parse function each).
- :mod:`crowdstudy.study.webio`: route rows, bodies (JSON only, streamed cap), responses, security
  headers, answer timing.
- :mod:`crowdstudy.study.admin`: admin authentication (header or cookie, never the URL).
- :mod:`crowdstudy.study.media`: videos under opaque names, published for a static server.
- :mod:`crowdstudy.study.quality`: screen, fullscreen, attention checks; exclusion rules.
- :mod:`crowdstudy.study.roster`: participant status, listing, withdrawal with an audit line.
- :mod:`crowdstudy.study.pg_local`: a throwaway PostgreSQL cluster (tests, benchmark).
- :mod:`crowdstudy.study.server`: a StudyConfig from the files (design, stimuli, consent, db).
- :mod:`crowdstudy.study.consent`: the consent Markdown file as safe HTML.
- :mod:`crowdstudy.study.export`: responses.csv / demographics.csv from a database.
- :mod:`crowdstudy.study.dashboard`: the admin progress page.
- :mod:`crowdstudy.study.bots`: simulated participants answering through the HTTP API (they
  read their trials' conditions from the admin API).
- :mod:`crowdstudy.study.fake_stimuli`: a tiny stimulus folder for tests and demos.
- :mod:`crowdstudy.study.local_server`: ``crowdstudy serve`` as a child process on a free port.
"""

__all__: list[str] = []

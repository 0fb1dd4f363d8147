"""The live view: a session served over the Foxglove WebSocket protocol while it runs (`--foxglove [PORT]`).

`channels` (topics and JSON schemas), `view` (pure: recorded messages in, live messages out), `events` (the
`foxglove.Log` lines), `server` (the foxglove-sdk server), `feed` (view + server inside the recorder process),
`link` (the parent's notice pipe: address, `--foxglove-wait`), `cli` (the options). See docs/foxglove/README.md.
"""

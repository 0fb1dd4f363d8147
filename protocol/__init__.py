"""The wire, imported as `sea_hil.protocol`: CAN (DBC `sea.dbc`, frames, codec, feedback assembly, bus), Zenoh
(keys, payloads, session, security) and link emulation. Nothing here knows a node; the plant, the controller, the
recorder and the session build on it."""

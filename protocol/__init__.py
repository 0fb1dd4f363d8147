"""Everything that crosses or observes the wire: DBC, codecs, Zenoh keys and payloads, bridge, link
emulation, statistics, MCAP recording, and the shared configuration and limb mechanics that give the wire
quantities (angles, spring deflections, voltages) their physical meaning."""

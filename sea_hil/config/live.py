"""Config of the live view: the Foxglove WebSocket server fed from the recorder (`sea_hil.live`)."""
from __future__ import annotations

from pydantic import Field

from sea_hil.config.base import _Frozen


class LiveConfig(_Frozen):
    enabled: bool = Field(False, description="serve the session live over the Foxglove WebSocket protocol")
    host: str = Field("127.0.0.1", min_length=1, description="interface to listen on (loopback unless set)")
    port: int = Field(8765, ge=0, le=65535, description="TCP port; 0 = a free port chosen by the system")
    wait: bool = Field(False, description="hold the session until a client has subscribed to a channel")
    wait_timeout_s: float = Field(600.0, gt=0, description="give up waiting for a client after this long")
    period_s: float = Field(0.1, gt=0, description="link / bus statistics every period_s of log time")
    window_s: float = Field(1.0, gt=0, description="sliding window of the messages/s, bytes/s and bus load rates")
    linger_s: float = Field(2.0, ge=0, description="after the session, serve until clients unsubscribe, at most this")
    backlog_messages: int = Field(8192, gt=0, description="outgoing messages buffered per client (oldest dropped)")

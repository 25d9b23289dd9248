"""Node ``viz``: the Foxglove WebSocket bridge (foxglove-sdk server) showing what the display believes, in
3-D."""

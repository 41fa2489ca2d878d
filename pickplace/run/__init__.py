"""One run request, validated once at the edge, planned, simulated and recorded."""

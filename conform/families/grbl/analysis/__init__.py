"""The grbl analyser: a capture of grbl traffic -> exchanges, the receive-buffer replay, metrics
and findings (analyze), its HTML report (htmlreport), and reference streaming senders run in
virtual time (streaming)."""

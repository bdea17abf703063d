"""Run reports: ``RUN/report.html``, one self-contained page per run folder (curves, what the
fit estimated, event windows beside renders, the mesh in a 3D viewer, the scores), and a
batch's ``index.html`` linking them. They only read run folders."""

from hybridneus.report.content import RunContent, read_run
from hybridneus.report.index import write_index
from hybridneus.report.run import FILENAME, write_report

__all__ = ["FILENAME", "RunContent", "read_run", "write_index", "write_report"]

"""A saved view read back with rerun's dataframe API (``rr.chunk.RrdReader`` → DataFusion).

``entity_table(path, entity)`` gives one pandas frame per entity on the ``time`` line: a
``time`` column (s, the log's clock) and one column per component (``Scalars:scalars``,
``Points2D:labels``, ...). Needs ``rerun-sdk[catalog]`` (DataFusion; the ``dev`` extra).
"""

from __future__ import annotations

import numpy as np

from .rrlog import TIMELINE


def load(path):
    """The recording of an .rrd file as a rerun ChunkStore."""
    import rerun as rr

    return rr.chunk.RrdReader(str(path)).stream().collect()


def entities(store) -> set[str]:
    """Entity paths that hold data (the properties left out)."""
    return {c.entity_path for c in store.schema().component_columns() if not c.entity_path.startswith("/__")}


def entity_table(store, entity: str):
    """The rows of one entity on the time line, sorted by time (pandas), time in seconds."""
    df = store.reader(index=TIMELINE, contents=entity).to_pandas()
    t = df[TIMELINE]
    df[TIMELINE] = t.dt.total_seconds() if hasattr(t, "dt") else np.asarray(t, np.float64) * 1e-9
    return df.sort_values(TIMELINE).reset_index(drop=True)

"""The fields ``animegraph query`` may order by: their own module, so that building the
command line (``--help``) does not import the query engine (DuckDB, pandas, pyarrow)."""

#: Fields a query may be ordered by, per mode.
ANIME_FIELDS = ("node_id", "clip_id", "phoneme", "emotion", "speaker", "start_time",
                "duration")
CLIP_FIELDS = ("clip_id", "emotion", "speaker", "duration", "n_animes")

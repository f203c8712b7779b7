"""The file types a database's motion is written as, by what the motion is: their own
module, free of imports, so that ``--help`` lists them without loading the writers."""

#: Name ending that selects Live Link Face CSV (ARKit databases) over the channel CSV.
LIVELINK_SUFFIX = ".livelink.csv"

#: The file that keeps every channel of a database's motion (what
#: :func:`animegraph.motion.files.motion_suffix` picks, in this order), and what it is for:
#: ``query --export`` writes it and ``query --help`` lists it from here.
EXPORT_FORMATS = {
    LIVELINK_SUFFIX: "Live Link Face CSV for ARKit blendshape databases",
    ".c3d": "C3D for databases whose channels are all points",
    ".csv": "frame,time,<channel> CSV otherwise",
}

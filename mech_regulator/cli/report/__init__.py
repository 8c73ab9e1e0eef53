"""What the command line shows and writes, one module per kind of output: terminal.py (scene text made safe to
show, notes, the progress of long work), machine_text.py (`describe` and the run summaries), analysis_text.py (the
analysis commands' answers), data.py (strict JSON and CSV) and outputs.py (the output files: their paths checked
before any work, each written after it).

Light to import (the standard library only at module level): the ROS launcher and the command line's parser import
it; numpy, the model and the scene load inside the functions that need them.
"""

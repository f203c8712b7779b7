"""The speech front end, shared by ingest (recorded speech) and synthesis (new speech).

Both sides must turn speech into phones and prosody with the same code, or the search
compares unlike things (Cao et al. 2005, §4.1-4.2):

* :mod:`.phones` -- the phone set (ARPAbet, 39 phones plus ``SIL``), viseme classes;
* :mod:`.g2p` -- pronunciations (CMUdict, eSpeak NG letter-to-sound);
* :mod:`.espeak` -- eSpeak NG speech synthesis with its phoneme events;
* :mod:`.segment` -- phones from speech: given labels, forced alignment of a transcript
  or phone recognition (PocketSphinx), and their error measures;
* :mod:`.ctc` -- the second phone engine, a CTC phone recogniser shipped in the ``hama``
  wheel: recognition, CTC-Viterbi forced alignment, per-frame phone posteriors;
* :mod:`.engines` -- the engines' names and which does what by default;
* :mod:`.words` -- phones aligned inside the words of a known word alignment;
* :mod:`.features` -- RASTA-PLP prosody curves and MFCCs.

Imports: ``db`` and the file formats of ``ingest``.
"""

"""The emotion classifier of Cao et al. (2005, §6); it lives in :mod:`ingest.emotion.classifier`.

Ingest trains it on a database's speech (so ``ingest`` must own it: ``ingest`` may not import
``animegraph``); this module keeps the historical import path working.
"""

from ingest.emotion.classifier import (
    EMODB_EMOTIONS,
    FEATURE_SAMPLE_RATE,
    MIN_DURATION,
    N_CEPSTRUM,
    EmotionClassifier,
    emotion_features,
    load_emodb,
    real_cepstrum,
    rich_features,
    speaker_normalize,
)

__all__ = [
    "EMODB_EMOTIONS",
    "FEATURE_SAMPLE_RATE",
    "MIN_DURATION",
    "N_CEPSTRUM",
    "EmotionClassifier",
    "emotion_features",
    "load_emodb",
    "real_cepstrum",
    "rich_features",
    "speaker_normalize",
]

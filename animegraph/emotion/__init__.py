"""Emotion classification of speech (Cao et al. 2005, §6)."""

from animegraph.emotion.classifier import (
    EMODB_EMOTIONS,
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
    "N_CEPSTRUM",
    "EmotionClassifier",
    "emotion_features",
    "load_emodb",
    "real_cepstrum",
    "rich_features",
    "speaker_normalize",
]

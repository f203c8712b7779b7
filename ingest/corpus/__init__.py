"""Corpus generators: the synthetic expressive speech + facial motion-capture corpus."""

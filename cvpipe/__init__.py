"""cvpipe: reproducible classical computer-vision pipelines."""

__version__ = "0.1.0"

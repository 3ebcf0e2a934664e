"""Mitsuba 3: the backend (Python route with warm workers, and the `mitsuba` executable), its worker process, spectral images (specfilm), and the LLVM and CUDA probes that choose its variants."""

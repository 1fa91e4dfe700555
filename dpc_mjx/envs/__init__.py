"""DPC environments (brax API). So far: the paper's reward (`rewards`)."""

"""The remote palpation application (the CoCo paper's section 6.1): its generated session."""

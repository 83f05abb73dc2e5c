"""Experience replay: whole episodes and the HER sampler (``buffer``), and MEP's episode priorities (``mep``)."""

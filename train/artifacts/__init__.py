"""What training leaves behind and users load: ``policies`` (any saved policy, checked against an environment)
and ``bundle`` (the policies of a comparison shipped inside the package with a card, in ``train/bundled``)."""

"""Built-in example networks (data files of :mod:`oxyline.catalogue`; load one by name with
``oxyline.load_model("bifurcation")`` or ``oxyline.catalogue.load("bifurcation")``)."""

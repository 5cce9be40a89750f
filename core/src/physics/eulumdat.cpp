// placeholder: filled in by the photometry parser work

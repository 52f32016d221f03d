"""Still sky images: reading image files (:mod:`.read`), star detection that holds on real
frames (:mod:`.detect`), and the per-image products of a plate solution (:mod:`.wcs`,
:mod:`.annotate`, :mod:`.star_names`)."""

"""Pictures of a study for looking at, not radiometric products: the Mitsuba scene of the satellite
over the Earth with its camera (:mod:`simcore.picture.scene`) and the annotated ``sunsim view``
picture (:mod:`simcore.picture.view`)."""

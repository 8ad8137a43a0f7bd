//! Power-of-two slice binning of rectangles into texture atlases. (Being written: see issue 4.)

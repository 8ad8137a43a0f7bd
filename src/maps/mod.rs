//! Offset transfer maps: crop, OpenEXR, index, CPU apply (Sec. 3, 5.1). Being written.

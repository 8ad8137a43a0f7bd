//! Offset selection (Sec. 3.1, 5.1, Appendix A). Being written.

"""wolfcal.intrinsics"""

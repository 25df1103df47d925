"""wolfcal.hardware"""

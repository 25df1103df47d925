"""wolfcal.vision"""

"""wolfcal.capture"""
